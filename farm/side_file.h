// A side file of the run folder (the sparse method's dense rows and weights, the visibility job's
// chunks): positioned writes and reads, fdatasync on demand. FileIoError names the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace prt {

class SideFile {
 public:
  // Opens (creating it if missing) `path` for reading and writing.
  explicit SideFile(std::string path);
  ~SideFile();
  SideFile(const SideFile&) = delete;
  SideFile& operator=(const SideFile&) = delete;

  void Write(const void* data, std::size_t bytes, uint64_t offset);
  // False when the file ends before offset + bytes.
  bool Read(void* data, std::size_t bytes, uint64_t offset) const;
  // fdatasync when anything was written since the last Sync.
  void Sync();
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
  bool dirty_ = false;
};

}  // namespace prt
