#pragma once
// Host-side data parallelism for the double-precision reference paths and host sums.
#include <algorithm>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace specbake {

// Runs fn(i) for i in [0, n) on up to 16 hardware threads (i interleaved over threads); fn must
// write only its own i's results, so the outcome does not depend on the thread count. An
// exception from fn stops that thread's remaining work; after every thread has joined, the
// first one thrown is rethrown on the calling thread (never std::terminate in a worker).
template <class Fn>
void parallel_for(long long n, Fn&& fn) {
  const long long threads = std::min<long long>({16, std::max(1u, std::thread::hardware_concurrency()), n});
  if (threads <= 1) {
    for (long long i = 0; i < n; ++i) fn(i);
    return;
  }
  std::vector<std::thread> pool;
  std::exception_ptr first;
  std::mutex m;
  for (long long t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      try {
        for (long long i = t; i < n; i += threads) fn(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(m);
        if (!first) first = std::current_exception();
      }
    });
  for (auto& th : pool) th.join();
  if (first) std::rethrow_exception(first);
}

// Runs fn(first, last, k) over [0, n) cut into fixed chunks of `chunk` elements (chunk k is
// [k·chunk, min(n, (k + 1)·chunk))), the chunks on the hardware threads. Per-chunk partial
// results combined in chunk order give the same bytes whatever the thread count.
template <class Fn>
void parallel_chunks(std::size_t n, std::size_t chunk, Fn&& fn) {
  const long long chunks = static_cast<long long>((n + chunk - 1) / chunk);
  parallel_for(chunks, [&](long long k) {
    const std::size_t first = static_cast<std::size_t>(k) * chunk;
    fn(first, std::min(n, first + chunk), static_cast<std::size_t>(k));
  });
}

}  // namespace specbake
