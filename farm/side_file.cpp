// pwrite/pread/fdatasync on a side file of the run folder (see side_file.h).
#include "farm/side_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "vocabulary/errors.h"

namespace prt {

SideFile::SideFile(std::string path) : path_(std::move(path)) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw FileIoError(path_, std::string("cannot open: ") + std::strerror(errno));
}

SideFile::~SideFile() {
  if (fd_ >= 0) ::close(fd_);
}

void SideFile::Write(const void* data, std::size_t bytes, uint64_t offset) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd_, p, bytes, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw FileIoError(path_, std::string("write failed: ") + std::strerror(errno));
    }
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  dirty_ = true;
}

bool SideFile::Read(void* data, std::size_t bytes, uint64_t offset) const {
  char* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd_, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw FileIoError(path_, std::string("read failed: ") + std::strerror(errno));
    if (n == 0) return false;
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  return true;
}

void SideFile::Sync() {
  if (!dirty_) return;
  if (::fdatasync(fd_) != 0)
    throw FileIoError(path_, std::string("fdatasync failed: ") + std::strerror(errno));
  dirty_ = false;
}

}  // namespace prt
