#pragma once
// Runs a piece of work in a child process, so that a library that crashes, hangs or allocates without bound on a
// hostile input (assimp on a corrupt mesh file) takes down only the child: the caller gets an error message and
// keeps running. POSIX (fork + pipe); the child runs only `work` and leaves with _exit.
#include <cstddef>
#include <functional>
#include <string>

namespace diffdope {

struct IsolationLimits {
  double timeout_s = 120;           // the child is killed after this long
  size_t address_space_bytes = 0;   // RLIMIT_AS of the child (0: none; ignored in sanitizer builds)
};

/// The bytes `work` returns, computed in a child process. Throws std::runtime_error with work's own message
/// when it throws, and one prefixed by `what` when the child dies of a signal (named), exceeds the time limit or
/// exits without an answer.
std::string run_isolated(const std::function<std::string()>& work, const IsolationLimits& limits,
                         const std::string& what);

}  // namespace diffdope
