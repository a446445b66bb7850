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
//
// SoloRunner (below) does the same for a solo model (Bailando: a dancer to
// music alone): music rows in, joint positions out, paced by the game
// thread's Take (the worker computes frames only while its output ring has
// room, so none are dropped). SessionRunner refuses a solo model
// (Status() DUO_INVALID_ARGUMENT) and SoloRunner a Duolando model.
#pragma once

#include "duolando.h"

#include <algorithm>
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
    duo_model_info info;
    status_ = duo_model_get_info(model, &info);
    if (status_ == DUO_OK && info.family != DUO_FAMILY_DUOLANDO) {
      status_ = DUO_INVALID_ARGUMENT;  // a solo model: SoloRunner
      return;
    }
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

// One solo frame: world joint positions (metres, SMPL-X axes: convert with
// duo_vec3_to_unreal) of the 24 SMPL joints, 60 frames per second.
struct SoloFrame {
  uint64_t index;
  float positions[DUO_BAILANDO_JOINTS * 3];
};

// A solo (Bailando) session on its own worker thread. The game thread
// submits music rows (duo_model_info.music_features floats each, one row
// per token: 7.5 per second) or gives the whole track at construction,
// calls Finish() at the end of the music, and takes frames as it plays
// them. The worker pushes the rows in order and pulls frames (the pull runs
// the model) while the output ring has room: the game thread's Take paces
// it, so no frame is ever dropped; a consumer that stops taking stops the
// worker, not the dance. A row the library rejects as non-finite or out of
// range is replaced by the last good row (RejectedRows()). Nothing
// allocates after construction.
class SoloRunner {
 public:
  // Creates the session (on the calling thread) and starts the worker.
  // seed: 2 tokens (up, down). `music_track` (rows x music_features
  // floats, or NULL) is COPIED into the session, which then holds every
  // row: config.music_buffer_frames is raised to the track's rows if
  // lower. queue_rows: music rows SubmitMusic may queue; queue_frames:
  // frames computed ahead of Take. Check Status() == DUO_OK (a Duolando
  // model: DUO_INVALID_ARGUMENT).
  SoloRunner(const duo_model* model, duo_session_config config, const uint32_t seed[2],
             const float* music_track = nullptr, size_t music_floats = 0, size_t queue_rows = 64,
             size_t queue_frames = 64)
      : out_(queue_frames) {
    duo_model_info info;
    status_ = duo_model_get_info(model, &info);
    if (status_ != DUO_OK) return;
    if (info.family != DUO_FAMILY_BAILANDO || info.joints != DUO_BAILANDO_JOINTS || info.music_features == 0) {
      status_ = DUO_INVALID_ARGUMENT;  // a Duolando model: SessionRunner
      return;
    }
    features_ = info.music_features;
    if (music_track != nullptr && music_floats > 0) {
      size_t rows = music_floats / features_;
      if (config.music_buffer_frames < rows) config.music_buffer_frames = static_cast<uint32_t>(std::min<size_t>(rows, UINT32_MAX));
    }
    status_ = duo_session_new(model, &config, seed, &session_);
    if (status_ == DUO_OK && music_track != nullptr)
      status_ = duo_session_set_music_track(session_, music_track, music_floats);
    if (status_ != DUO_OK) return;
    rows_capacity_ = queue_rows ? queue_rows : 1;
    rows_.assign(rows_capacity_ * features_, 0.0f);
    row_.assign(features_, 0.0f);
    last_good_.assign(features_, 0.0f);
    worker_ = std::thread([this] { Run(); });
  }

  ~SoloRunner() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_one();
    if (worker_.joinable()) worker_.join();
    duo_session_free(session_);
  }

  SoloRunner(const SoloRunner&) = delete;
  SoloRunner& operator=(const SoloRunner&) = delete;

  duo_result Status() const { return status_; }
  size_t MusicFeatures() const { return features_; }

  // Game thread: queues up to n_rows whole music rows (n_rows x
  // MusicFeatures() floats); returns how many were queued (fewer when the
  // queue is full: submit the rest later). Rows after Finish() are ignored.
  size_t SubmitMusic(const float* rows, size_t n_rows) {
    size_t n = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finish_requested_) return 0;
      for (; n < n_rows && rows_count_ < rows_capacity_; ++n) {
        size_t slot = (rows_head_ + rows_count_) % rows_capacity_;
        std::memcpy(&rows_[slot * features_], rows + n * features_, features_ * sizeof(float));
        ++rows_count_;
      }
    }
    if (n) cv_.notify_one();
    return n;
  }

  // Game thread: the music has ended (after the rows submitted so far).
  // The session pads it as the authors' demo does and dances to its end.
  void Finish() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      finish_requested_ = true;
    }
    cv_.notify_one();
  }

  // Game thread: moves up to `max` frames (oldest first) into `out`;
  // returns how many. Frees room: the worker computes more.
  size_t Take(SoloFrame* out, size_t max) {
    size_t n = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      while (n < max && out_.Pop(&out[n])) ++n;
    }
    if (n) cv_.notify_one();
    return n;
  }

  // Game thread: true once Finish() was processed and every frame of the
  // dance has been computed (Take may still hold some).
  bool Ended() {
    std::lock_guard<std::mutex> lock(mu_);
    return ended_;
  }
  uint64_t RejectedRows() {
    std::lock_guard<std::mutex> lock(mu_);
    return rejected_;
  }
  // The first unexpected result of the worker (DUO_OK if none).
  duo_result WorkerError() {
    std::lock_guard<std::mutex> lock(mu_);
    return worker_error_;
  }

 private:
  void Run() {
    SoloFrame f;
    bool blocked = false;    // the session's music buffer is full: pull first
    bool exhausted = false;  // the last pull was DUO_NOT_READY and nothing came in since
    bool finished = false;   // duo_session_finish called
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      cv_.wait(lock, [&] {
        return stop_ || (rows_count_ > 0 && !blocked) || (finish_requested_ && rows_count_ == 0 && !finished) ||
               (!exhausted && !out_.Full());
      });
      if (stop_) return;
      if (rows_count_ > 0 && !blocked) {
        std::memcpy(row_.data(), &rows_[rows_head_ * features_], features_ * sizeof(float));
        lock.unlock();
        duo_result r = duo_session_push_music(session_, row_.data(), features_);
        bool rejected = false;
        if (r == DUO_NON_FINITE_INPUT) {
          rejected = true;
          r = duo_session_push_music(session_, last_good_.data(), features_);
        } else if (r == DUO_OK) {
          last_good_ = row_;
        }
        lock.lock();
        if (r == DUO_BACKLOG) {
          blocked = true;  // the row stays queued
          exhausted = false;
        } else {
          rows_head_ = (rows_head_ + 1) % rows_capacity_;
          --rows_count_;
          if (rejected) ++rejected_;
          if (r == DUO_OK) {
            exhausted = false;
          } else if (worker_error_ == DUO_OK) {
            worker_error_ = r;
          }
        }
      } else if (finish_requested_ && rows_count_ == 0 && !finished) {
        lock.unlock();
        duo_result r = duo_session_finish(session_);
        lock.lock();
        finished = true;
        exhausted = false;
        if (r != DUO_OK) {  // e.g. no music at all
          if (worker_error_ == DUO_OK) worker_error_ = r;
          ended_ = true;
        }
      } else {
        lock.unlock();
        duo_result r = duo_session_pull_positions(session_, f.positions, DUO_BAILANDO_JOINTS * 3, &f.index);
        lock.lock();
        if (r == DUO_OK) {
          out_.Push(f);  // never full here: checked before the pull
          blocked = false;
        } else {
          exhausted = true;
          if (r != DUO_NOT_READY && worker_error_ == DUO_OK) worker_error_ = r;
          if (finished) ended_ = true;
          // Full music buffer and nothing to pull: cannot happen by the
          // session's rules; stop pushing rather than spin.
          if (blocked && r == DUO_NOT_READY && worker_error_ == DUO_OK) worker_error_ = DUO_BACKLOG;
        }
      }
    }
  }

  duo_session* session_ = nullptr;
  duo_result status_ = DUO_INTERNAL;
  size_t features_ = 0;
  std::vector<float> rows_;       // rows_capacity_ x features_, a ring
  size_t rows_capacity_ = 1;
  size_t rows_head_ = 0;
  size_t rows_count_ = 0;
  std::vector<float> row_;        // worker: the row being pushed
  std::vector<float> last_good_;  // worker: the last row the session took
  std::mutex mu_;
  std::condition_variable cv_;
  Ring<SoloFrame> out_;
  bool stop_ = false;
  bool finish_requested_ = false;
  bool ended_ = false;
  uint64_t rejected_ = 0;
  duo_result worker_error_ = DUO_OK;
  std::thread worker_;
};

}  // namespace duolando
