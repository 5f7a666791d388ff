// Errors every stage reports to the user. InputError always names the file (and, where known,
// the line, pixel or record) and what is wrong with it.
#pragma once

#include <stdexcept>
#include <string>

namespace prt {

class InputError : public std::runtime_error {
 public:
  InputError(const std::string& file, const std::string& what)
      : std::runtime_error(file + ": " + what), file_(file) {}
  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

// A failure of the operating system to create, write, sync or rename a file (disk full,
// read-only or missing folder). Names the file and the system's reason.
class FileIoError : public std::runtime_error {
 public:
  FileIoError(const std::string& file, const std::string& what)
      : std::runtime_error(file + ": " + what), file_(file) {}
  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

// A NaN or Inf found at a stage boundary; `where` says which stage and which element.
class NumericalError : public std::runtime_error {
 public:
  explicit NumericalError(const std::string& where) : std::runtime_error(where) {}
};

}  // namespace prt
