// Durable files and positioned I/O (see durable_file.h).
#include "vocabulary/durable_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "vocabulary/errors.h"

namespace prt {

std::string SystemReason(const std::string& what) {
  return what + ": " + std::strerror(errno);
}

void PwriteAll(int fd, const void* data, std::size_t bytes, uint64_t offset,
               const std::string& path) {
  const auto* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw FileIoError(path, SystemReason("write failed"));
    }
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
}

bool PreadAll(int fd, void* data, std::size_t bytes, uint64_t offset, const std::string& path) {
  auto* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw InputError(path, SystemReason("read failed"));
    }
    if (n == 0) return false;
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  return true;
}

uint64_t FileSize(int fd, const std::string& path) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) throw InputError(path, SystemReason("cannot stat"));
  return static_cast<uint64_t>(st.st_size);
}

void SyncDirectory(const std::string& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw FileIoError(dir, SystemReason("cannot open folder"));
  const int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0 && errno != EINVAL) throw FileIoError(dir, SystemReason("fsync of folder failed"));
}

void WriteFileDurably(const std::string& path, std::string_view bytes) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw FileIoError(tmp, SystemReason("cannot create"));
  try {
    PwriteAll(fd, bytes.data(), bytes.size(), 0, tmp);
    if (::fsync(fd) != 0) throw FileIoError(tmp, SystemReason("fsync failed"));
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());  // a full disk leaves no stray temporary file behind
    throw;
  }
  ::close(fd);
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const FileIoError error(path, SystemReason("cannot rename " + tmp + " to it"));
    ::unlink(tmp.c_str());
    throw error;
  }
  SyncDirectory(std::filesystem::path(path).parent_path().string());
}

std::string ReadWholeFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw InputError(path, SystemReason("cannot open"));
  std::string bytes;
  try {
    bytes.resize(static_cast<std::size_t>(FileSize(fd, path)));
    if (!PreadAll(fd, bytes.data(), bytes.size(), 0, path)) {
      throw InputError(path, "file shrank while being read");
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
  return bytes;
}

}  // namespace prt
