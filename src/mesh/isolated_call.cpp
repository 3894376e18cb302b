#include "mesh/isolated_call.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <new>
#include <stdexcept>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define DIFFDOPE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define DIFFDOPE_SANITIZED 1
#endif
#endif

#ifdef DIFFDOPE_SANITIZED
#include <sanitizer/common_interface_defs.h>
#endif

namespace diffdope {
namespace {

bool write_all(int fd, const char* p, size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w, n -= size_t(w);
  }
  return true;
}

/// The child: runs work, writes 'O' + result or 'E' + message, and leaves without running the parent's
/// destructors or atexit handlers (they belong to the parent).
[[noreturn]] void child_main(int fd, const std::function<std::string()>& work, const IsolationLimits& limits) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // do not outlive a parent that was killed
  // A crash here must end the child by its signal, which the parent names: not run the parent's crash handlers
  // (a backtrace printer, a fuzzer's, a sanitizer's), which belong to the parent and may report or exit otherwise.
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) ::signal(sig, SIG_DFL);
#ifdef DIFFDOPE_SANITIZED
  __sanitizer_set_death_callback(nullptr);  // (libFuzzer's would write the parent's input as a crash)
#endif
#ifndef DIFFDOPE_SANITIZED             // (sanitizers reserve terabytes of address space)
  if (limits.address_space_bytes > 0) {
    const rlimit r{rlim_t(limits.address_space_bytes), rlim_t(limits.address_space_bytes)};
    ::setrlimit(RLIMIT_AS, &r);
  }
#else
  (void)limits;
#endif
  std::string out;
  int code = 0;
  try {
    out = "O" + work();
  } catch (const std::bad_alloc&) {
    out = "Eran out of memory";
    code = 1;
  } catch (const std::exception& e) {
    out = std::string("E") + e.what();
    code = 1;
  } catch (...) {
    out = "Efailed with an unknown error";
    code = 1;
  }
  ::_exit(write_all(fd, out.data(), out.size()) ? code : 2);
}

}  // namespace

std::string run_isolated(const std::function<std::string()>& work, const IsolationLimits& limits,
                         const std::string& what) {
  auto fail = [&](const std::string& m) -> std::runtime_error { return std::runtime_error(what + ": " + m); };
  int fds[2];
  pid_t pid;
  {
    // Two calls on two threads: the second child must not inherit the first one's write end (the first parent
    // would then wait for both children to end before it sees its answer complete).
    static std::mutex forking;
    const std::lock_guard<std::mutex> lock(forking);
    if (::pipe2(fds, O_CLOEXEC) != 0) throw fail(std::string("cannot create a pipe: ") + std::strerror(errno));
    std::fflush(nullptr);  // else the child holds a copy of unwritten output
    pid = ::fork();
    if (pid < 0) {
      ::close(fds[0]), ::close(fds[1]);
      throw fail(std::string("cannot start a child process: ") + std::strerror(errno));
    }
    if (pid == 0) {
      ::close(fds[0]);
      child_main(fds[1], work, limits);
    }
    ::close(fds[1]);
  }
  std::string data;
  bool timed_out = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(limits.timeout_s);
  char buf[1 << 16];
  for (;;) {
    const double left = std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
    if (left <= 0) {
      timed_out = true;
      break;
    }
    pollfd p{fds[0], POLLIN, 0};
    const int r = ::poll(&p, 1, int(std::min(left * 1000.0 + 1.0, 1e9)));
    if (r < 0 && errno == EINTR) continue;
    if (r == 0) continue;  // (the deadline check above ends the wait)
    const ssize_t n = ::read(fds[0], buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // EOF: the child is done (or gone)
    data.append(buf, size_t(n));
  }
  ::close(fds[0]);
  if (timed_out) ::kill(pid, SIGKILL);
  int status = 0;
  pid_t w;
  do w = ::waitpid(pid, &status, 0);
  while (w < 0 && errno == EINTR);
  const bool reaped = w == pid;  // (false when the process ignores SIGCHLD: children are reaped for it)
  if (timed_out) throw fail("took longer than " + std::to_string(int(limits.timeout_s)) + " s and was stopped");
  if (reaped && WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    throw fail("crashed (signal " + std::to_string(sig) + ", " + strsignal(sig) +
               ") on this input: the file is corrupt or uses something the importer mishandles");
  }
  if (data.empty()) throw fail("the child process ended without an answer");
  if (data[0] == 'E') throw std::runtime_error(data.substr(1));  // work's own message, as it is
  if (data[0] != 'O' || (reaped && (!WIFEXITED(status) || WEXITSTATUS(status) != 0)))
    throw fail("the child process ended abnormally");
  return data.substr(1);
}

}  // namespace diffdope
