// DuolandoRunner.h — runs one duolando session on its own worker thread,
// fed and drained by the game thread. Plain C++17 (no Unreal types), so
// the same code is compiled and run under valgrind in CI
// (tests/c/test_runner.cpp) and used by UDuolandoFollowerComponent.
//
// Threads: Submit / Take / counters are called from ONE game thread; the
// worker thread alone touches the duo_session (the session's rule: one
// thread at a time). The two meet at two fixed-capacity rings guarded by
// one mutex; nothing allocates after construction.
//
// Input policy: a leader frame the library rejects as non-finite or out
// of range is replaced by the last good frame (the 30 fps clock keeps
// running); RejectedFrames() counts them. If the game thread stops
// draining, the output ring overwrites its oldest frames (DroppedFrames()).
#pragma once

#include "duolando.h"

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace duolando {

template <typename T>
class Ring {
 public:
  explicit Ring(size_t capacity) : items_(capacity ? capacity : 1) {}
  bool Empty() const { return count_ == 0; }
  bool Full() const { return count_ == items_.size(); }
  // Appends; when full, overwrites the oldest and returns false.
  bool Push(const T& v) {
    bool room = !Full();
    if (!room) Pop(nullptr);
    items_[(head_ + count_) % items_.size()] = v;
    ++count_;
    return room;
  }
  bool Pop(T* out) {
    if (count_ == 0) return false;
    if (out) *out = items_[head_];
    head_ = (head_ + 1) % items_.size();
    --count_;
    return true;
  }

 private:
  std::vector<T> items_;
  size_t head_ = 0;
  size_t count_ = 0;
};

class SessionRunner {
 public:
  // Creates the session (on the calling thread) and starts the worker.
  // `music_track` (frames x music_features floats) is borrowed: keep it
  // alive until the runner is destroyed. Check Status() == DUO_OK.
  SessionRunner(const duo_model* model, const duo_session_config& config, const uint32_t seed[5],
                const float* music_track, size_t music_floats, size_t queue_frames = 64)
      : in_(queue_frames), out_(queue_frames) {
    status_ = duo_session_new(model, &config, seed, &session_);
    if (status_ == DUO_OK && music_track != nullptr)
      status_ = duo_session_set_music_track(session_, music_track, music_floats);
    if (status_ == DUO_OK) {
      std::memset(&last_good_, 0, sizeof last_good_);
      worker_ = std::thread([this] { Run(); });
    }
  }

  ~SessionRunner() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_one();
    if (worker_.joinable()) worker_.join();
    duo_session_free(session_);
  }

  SessionRunner(const SessionRunner&) = delete;
  SessionRunner& operator=(const SessionRunner&) = delete;

  duo_result Status() const { return status_; }

  // Game thread: queues a leader frame (SMPL-X; convert engine frames with
  // duo_leader_frame_convert first). Returns false when the input ring was
  // full and its oldest frame was dropped.
  bool Submit(const duo_leader_frame& frame) {
    bool room;
    {
      std::lock_guard<std::mutex> lock(mu_);
      room = in_.Push(frame);
    }
    cv_.notify_one();
    return room;
  }

  // Game thread: moves up to `max` ready follower frames (oldest first)
  // into `out`; returns how many.
  size_t Take(duo_follower_frame* out, size_t max) {
    std::lock_guard<std::mutex> lock(mu_);
    size_t n = 0;
    while (n < max && out_.Pop(&out[n])) ++n;
    return n;
  }

  // Game thread: true once every submitted frame has been processed.
  bool Idle() {
    std::lock_guard<std::mutex> lock(mu_);
    return in_.Empty() && !busy_;
  }

  uint64_t RejectedFrames() {
    std::lock_guard<std::mutex> lock(mu_);
    return rejected_;
  }
  uint64_t DroppedFrames() {
    std::lock_guard<std::mutex> lock(mu_);
    return dropped_;
  }
  // The first unexpected result of the worker (DUO_OK if none).
  duo_result WorkerError() {
    std::lock_guard<std::mutex> lock(mu_);
    return worker_error_;
  }

 private:
  void Run() {
    duo_leader_frame frame;
    duo_follower_frame f;
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      cv_.wait(lock, [this] { return stop_ || !in_.Empty(); });
      if (stop_) return;
      in_.Pop(&frame);
      busy_ = true;
      lock.unlock();
      // The costly part runs without the lock.
      duo_result r = duo_session_push_leader(session_, &frame);
      bool rejected = false;
      if (r == DUO_NON_FINITE_INPUT) {
        rejected = true;
        r = duo_session_push_leader(session_, &last_good_);
      } else if (r == DUO_OK) {
        last_good_ = frame;
      }
      lock.lock();
      if (rejected) ++rejected_;
      if (r != DUO_OK && r != DUO_BACKLOG && worker_error_ == DUO_OK) worker_error_ = r;
      lock.unlock();
      for (;;) {
        duo_result p = duo_session_pull_follower(session_, &f);
        if (p != DUO_OK) break;
        lock.lock();
        if (!out_.Push(f)) ++dropped_;
        lock.unlock();
      }
      lock.lock();
      busy_ = false;
    }
  }

  duo_session* session_ = nullptr;
  duo_result status_ = DUO_INTERNAL;
  duo_leader_frame last_good_;
  std::mutex mu_;
  std::condition_variable cv_;
  Ring<duo_leader_frame> in_;
  Ring<duo_follower_frame> out_;
  bool stop_ = false;
  bool busy_ = false;
  uint64_t rejected_ = 0;
  uint64_t dropped_ = 0;
  duo_result worker_error_ = DUO_OK;
  std::thread worker_;
};

}  // namespace duolando
