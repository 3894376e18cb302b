#pragma once
// A small persistent thread pool with parallel_for. Work items are independent and write only their own
// outputs, so results never depend on the number of threads or on scheduling.
#include <atomic>
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
  int active_ = 0;
  unsigned generation_ = 0;
  bool stop_ = false;
  std::exception_ptr error_;
};

}  // namespace diffdope
