// Files that survive a crash, and positioned I/O that names the file in its errors: what the farm
// and every later stage use to write and read their files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace prt {

// Writes `bytes` to path.tmp, fsyncs it, renames it over `path` and fsyncs the folder, so that
// `path` holds either its old or its new content after a crash. Throws FileIoError.
void WriteFileDurably(const std::string& path, std::string_view bytes);
// Whole file as bytes; throws InputError naming the file when it cannot be read.
std::string ReadWholeFile(const std::string& path);
// fsync of a folder (makes renames and creations inside it durable). Throws FileIoError.
void SyncDirectory(const std::string& dir);

// pwrite of every byte at `offset` (retrying short writes and EINTR); FileIoError names `path`.
void PwriteAll(int fd, const void* data, std::size_t bytes, uint64_t offset,
               const std::string& path);
// pread of `bytes` at `offset`; false at end of file before all were read. InputError on a
// read error.
bool PreadAll(int fd, void* data, std::size_t bytes, uint64_t offset, const std::string& path);
// "<what>: <strerror(errno)>", the reason a system call just failed.
std::string SystemReason(const std::string& what);
// Size of an open file; InputError when fstat fails.
uint64_t FileSize(int fd, const std::string& path);

}  // namespace prt
