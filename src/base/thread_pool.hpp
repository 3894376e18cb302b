#pragma once
// A small persistent thread pool with parallel_for. Work items are independent and write only their own
// outputs, so results never depend on the number of threads or on scheduling. A refinement calls it a few
// hundred times in a row with microseconds between calls: the threads spin for kSpin before they sleep, so a
// call does not pay the kernel's wake-up of a sleeping thread (2-3 % of the fast preset's time).
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace diffdope {

class ThreadPool {
 public:
  /// threads <= 0: std::thread::hardware_concurrency().
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }
  /// How long an idle thread polls for the next call (and the caller for the last worker) before it sleeps.
  static constexpr std::chrono::microseconds kSpin{100};

  /// Calls fn(index, worker) for index in [0, count); worker in [0, size()) identifies per-thread scratch.
  /// Not re-entrant from inside fn. The calling thread works too. Exceptions from fn are rethrown (the first one) after all work stops.
  void parallel_for(int count, const std::function<void(int index, int worker)>& fn);

 private:
  void worker_loop(int worker);
  void run_items(int worker);

  std::vector<std::thread> workers_;
  std::mutex call_mutex_;  // one parallel_for at a time (callers from several threads queue up)
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  const std::function<void(int, int)>* job_ = nullptr;
  int count_ = 0;
  std::atomic<int> next_{0};
  std::atomic<int> active_{0};          // workers still in the current call (changed under mutex_)
  std::atomic<unsigned> generation_{0};  // one more per call (changed under mutex_)
  std::atomic<bool> stop_{false};
  std::exception_ptr error_;
};

}  // namespace diffdope
