// For the runtime's and the viewer's tests: the message of the prt::NumericalError a call throws.
#pragma once

#include <string>

#include "vocabulary/errors.h"

namespace prt::testing {

// What `f()` throws as a NumericalError, or "no error" when it returns.
template <typename F>
std::string NumericalErrorOf(const F& f) {
  try {
    f();
  } catch (const NumericalError& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace prt::testing
