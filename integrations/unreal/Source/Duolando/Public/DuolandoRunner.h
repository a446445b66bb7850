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
// room, so none are dropped). TransflowerRunner does it for a Transflower
// model (a probabilistic solo dancer): audio rows in, motion features out.
// Both share RowRunner (the row queue and the worker loop). SessionRunner
// refuses a solo model (Status() DUO_INVALID_ARGUMENT), SoloRunner a
// Duolando or Transflower model, TransflowerRunner the other families.
// TransflowerStepBatch (last) owns a Transflower step batch: several
// sessions stepped one after another through one step's memory.
#pragma once

#include "duolando.h"

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>
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
  // With `batch` (a Duolando duo_step_batch made for `config` or a larger
  // one), the session is bound to it (duo_session_new_batched): 1.5 MB
  // less at full size, and the runners bound to one batch step one at a
  // time (its memory is behind the library's lock). The session keeps the
  // batch alive: the caller may free its handle at once.
  SessionRunner(const duo_model* model, const duo_session_config& config, const uint32_t seed[5],
                const float* music_track, size_t music_floats, size_t queue_frames = 64,
                duo_step_batch* batch = nullptr)
      : in_(queue_frames), out_(queue_frames) {
    duo_model_info info;
    status_ = duo_model_get_info(model, &info);
    if (status_ == DUO_OK && info.family != DUO_FAMILY_DUOLANDO) {
      status_ = DUO_INVALID_ARGUMENT;  // a solo model: SoloRunner
      return;
    }
    status_ = batch ? duo_session_new_batched(model, &config, seed, batch, &session_)
                    : duo_session_new(model, &config, seed, &session_);
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

// A fixed-capacity ring of rows of `width` floats, each with a tag (a
// frame index). Nothing allocates after construction.
class RowRing {
 public:
  RowRing(size_t capacity, size_t width)
      : data_((capacity ? capacity : 1) * width), tags_(capacity ? capacity : 1), width_(width) {}
  size_t Capacity() const { return tags_.size(); }
  size_t Size() const { return count_; }
  bool Empty() const { return count_ == 0; }
  bool Full() const { return count_ == tags_.size(); }
  void Clear() { head_ = count_ = 0; }
  // Appends a copy of `row` (width floats); call only when not Full().
  void Push(const float* row, uint64_t tag = 0) {
    size_t slot = (head_ + count_) % tags_.size();
    std::memcpy(&data_[slot * width_], row, width_ * sizeof(float));
    tags_[slot] = tag;
    ++count_;
  }
  // The oldest row; call only when not Empty().
  const float* Front() const { return &data_[head_ * width_]; }
  // Removes the oldest row, copied into `out` and its tag into `tag` (either may be NULL).
  bool Pop(float* out, uint64_t* tag) {
    if (count_ == 0) return false;
    if (out) std::memcpy(out, Front(), width_ * sizeof(float));
    if (tag) *tag = tags_[head_];
    head_ = (head_ + 1) % tags_.size();
    --count_;
    return true;
  }

 private:
  std::vector<float> data_;
  std::vector<uint64_t> tags_;
  size_t width_;
  size_t head_ = 0;
  size_t count_ = 0;
};

// The worker half SoloRunner and TransflowerRunner share: a session that
// takes rows of music features (duo_session_push_music) and makes a frame
// when pulled (the pull runs the model), on its own worker thread. The game
// thread queues rows (SubmitRows) and takes frames through the derived
// class (Take). The worker pushes the rows in order and pulls frames while
// the derived class's output ring has room: the game thread's Take paces
// it, so no frame is ever dropped; a consumer that stops taking stops the
// worker, not the dance, and then the rows back up (SubmitRows queues
// fewer). A row the library rejects as non-finite or out of range is
// replaced by the last good row (RejectedRows()). Nothing allocates after
// construction.
//
// Threads: SubmitRows, RowRoom, the counters and the derived class's Take /
// Finish / Reset are called from ONE game thread; the worker thread alone
// touches the duo_session. They meet at the rings, guarded by one mutex.
// Destruction joins the worker (it waits for at most the step in flight).
class RowRunner {
 public:
  RowRunner(const RowRunner&) = delete;
  RowRunner& operator=(const RowRunner&) = delete;

  duo_result Status() const { return status_; }
  // Floats per row.
  size_t RowFeatures() const { return features_; }

  // Game thread: queues up to n_rows whole rows (n_rows x RowFeatures()
  // floats); returns how many were queued (fewer when the queue is full:
  // submit the rest later). Rows after Finish() are ignored.
  size_t SubmitRows(const float* rows, size_t n_rows) {
    size_t n = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finish_requested_ || rows_ == nullptr) return 0;
      for (; n < n_rows && !rows_->Full(); ++n) rows_->Push(rows + n * features_);
    }
    if (n) cv_.notify_one();
    return n;
  }
  // Game thread: rows SubmitRows would queue now (only the worker takes
  // rows out, so the room can only grow until the next SubmitRows).
  size_t RowRoom() {
    std::lock_guard<std::mutex> lock(mu_);
    return rows_ ? rows_->Capacity() - rows_->Size() : 0;
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

 protected:
  RowRunner() = default;
  // Frees the session. A derived destructor calls Stop() first: the worker
  // calls its hooks.
  virtual ~RowRunner() {
    Stop();
    duo_session_free(session_);
  }

  // The derived constructor, once session_ is made, features_ set and its
  // output ring sized: the row queue (queue_rows rows) and the worker.
  void Start(size_t queue_rows) {
    rows_.reset(new RowRing(queue_rows, features_));
    row_.assign(features_, 0.0f);
    last_good_.assign(features_, 0.0f);
    worker_ = std::thread([this] { Run(); });
  }
  // Stops and joins the worker; idempotent.
  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_one();
    if (worker_.joinable()) worker_.join();
  }
  // Under mu_ (then notify cv_): the music has ended after the rows queued.
  void FinishLocked() { finish_requested_ = true; }
  // Under mu_ (then notify cv_): the queued rows dropped, the worker calls
  // ResetSession(arg) before anything else; a frame in flight is discarded.
  // The derived class clears its output ring under the same lock.
  void ResetLocked(uint64_t arg) {
    if (rows_) rows_->Clear();
    finish_requested_ = false;
    ended_ = false;
    reset_pending_ = true;
    reset_arg_ = arg;
    ++generation_;
  }

  // Worker hooks, called without the lock: the next frame into the derived
  // class's staging (DUO_OK, DUO_NOT_READY or an error); the session back
  // to its start.
  virtual duo_result PullFrame() = 0;
  virtual duo_result ResetSession(uint64_t) { return DUO_OK; }
  // Worker hooks, called under mu_: the output ring is full; the staged
  // frame into it (never full then).
  virtual bool OutputFull() const = 0;
  virtual void StoreFrame() = 0;

  std::mutex mu_;
  std::condition_variable cv_;
  duo_session* session_ = nullptr;
  duo_result status_ = DUO_INTERNAL;
  size_t features_ = 0;
  bool ended_ = false;  // under mu_: Finish processed and every frame made

 private:
  void Fail(duo_result r) {  // under mu_
    if (r != DUO_OK && worker_error_ == DUO_OK) worker_error_ = r;
  }

  void Run() {
    bool blocked = false;    // the session's music buffer is full: pull first
    bool exhausted = false;  // the last pull was DUO_NOT_READY and nothing came in since
    bool finished = false;   // duo_session_finish called
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      cv_.wait(lock, [&] {
        return stop_ || reset_pending_ || (!rows_->Empty() && !blocked) ||
               (finish_requested_ && rows_->Empty() && !finished) || (!exhausted && !OutputFull());
      });
      if (stop_) return;
      const uint64_t generation = generation_;  // a Reset while unlocked voids the result
      if (reset_pending_) {
        reset_pending_ = false;
        blocked = exhausted = finished = false;
        const uint64_t arg = reset_arg_;
        lock.unlock();
        std::fill(last_good_.begin(), last_good_.end(), 0.0f);
        duo_result r = ResetSession(arg);
        lock.lock();
        Fail(r);
      } else if (!rows_->Empty() && !blocked) {
        std::memcpy(row_.data(), rows_->Front(), features_ * sizeof(float));
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
        if (generation != generation_) continue;  // the rows are gone; the reset undoes the push
        if (r == DUO_BACKLOG) {
          blocked = true;  // the row stays queued
          exhausted = false;
        } else {
          rows_->Pop(nullptr, nullptr);
          if (rejected) ++rejected_;
          if (r == DUO_OK) exhausted = false;
          Fail(r);
        }
      } else if (finish_requested_ && rows_->Empty() && !finished) {
        lock.unlock();
        duo_result r = duo_session_finish(session_);
        lock.lock();
        if (generation != generation_) continue;
        finished = true;
        exhausted = false;
        if (r != DUO_OK) {  // e.g. no music at all
          Fail(r);
          ended_ = true;
        }
      } else {
        lock.unlock();
        duo_result r = PullFrame();
        lock.lock();
        if (generation != generation_) continue;  // a frame of before the Reset: discarded
        if (r == DUO_OK) {
          StoreFrame();  // never full here: checked before the pull
          blocked = false;
        } else {
          exhausted = true;
          if (r != DUO_NOT_READY) Fail(r);
          if (finished) ended_ = true;
          // Full music buffer and nothing to pull: cannot happen by the
          // session's rules; stop pushing rather than spin.
          if (blocked && r == DUO_NOT_READY) Fail(DUO_BACKLOG);
        }
      }
    }
  }

  std::unique_ptr<RowRing> rows_;  // the queued rows (features_ floats each)
  std::vector<float> row_;        // worker: the row being pushed
  std::vector<float> last_good_;  // worker: the last row the session took
  bool stop_ = false;
  bool finish_requested_ = false;
  bool reset_pending_ = false;
  uint64_t reset_arg_ = 0;
  uint64_t generation_ = 0;  // Resets so far
  uint64_t rejected_ = 0;
  duo_result worker_error_ = DUO_OK;
  std::thread worker_;
};

// One solo frame: world joint positions (metres, SMPL-X axes: convert with
// duo_vec3_to_unreal) of the 24 SMPL joints, 60 frames per second.
struct SoloFrame {
  uint64_t index;
  float positions[DUO_BAILANDO_JOINTS * 3];
};

// A solo (Bailando) session on its own worker thread (RowRunner above: its
// threading rule, pacing and input policy). The game thread submits music
// rows (duo_model_info.music_features floats each, one row per token: 7.5
// per second) or gives the whole track at construction, calls Finish() at
// the end of the music, and takes frames as it plays them.
class SoloRunner : public RowRunner {
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
    if (status_ == DUO_OK) Start(queue_rows);
  }
  ~SoloRunner() override { Stop(); }

  size_t MusicFeatures() const { return RowFeatures(); }

  // Game thread: SubmitRows (music rows).
  size_t SubmitMusic(const float* rows, size_t n_rows) { return SubmitRows(rows, n_rows); }

  // Game thread: the music has ended (after the rows submitted so far).
  // The session pads it as the authors' demo does and dances to its end.
  void Finish() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      FinishLocked();
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

 private:
  duo_result PullFrame() override {
    return duo_session_pull_positions(session_, staged_.positions, DUO_BAILANDO_JOINTS * 3, &staged_.index);
  }
  bool OutputFull() const override { return out_.Full(); }
  void StoreFrame() override { out_.Push(staged_); }

  SoloFrame staged_;  // worker: the frame being pulled
  Ring<SoloFrame> out_;
};

// A Transflower session (a probabilistic solo dancer, .duo family 2) on its
// own worker thread (RowRunner above: its threading rule, pacing and input
// policy): audio rows in (duo_transflower_info.audio_features floats each,
// 20 per second; frame t needs rows t .. t + audio_window - 1), frames of
// the model's motion features out (channels floats each, 20 per second).
// Each frame's step (tens of ms at the published size) runs on the worker,
// never on the game thread. The base samples come from the session's seeded
// RNG, or from a noise track given at construction (recorded noise: frame
// t takes its sample t while the track lasts; e.g. to replay a dance).
// There is no end of the music: the frames stop where the audio does.
class TransflowerRunner : public RowRunner {
 public:
  // Creates the session (on the calling thread) and starts the worker.
  // seed_motion (seed_rows x channels floats) and labels (one per style
  // input; NULL with 0 when none) are copied into the session, as
  // duo_transflower_session_new does; `noise` (whole samples of
  // noise_floats floats, or NULL with 0) is COPIED. queue_rows: audio rows
  // SubmitAudio may queue; queue_frames: frames computed ahead of Take.
  // Check Status() == DUO_OK: DUO_INVALID_ARGUMENT for a model of another
  // family, a config with batched = 1 (its pulls never step: a step batch
  // makes its frames) or a noise track of a partial sample; else as
  // duo_transflower_session_new.
  TransflowerRunner(const duo_model* model, const duo_transflower_config& config, const float* seed_motion,
                    size_t seed_floats, const uint32_t* labels, size_t n_labels, const float* noise = nullptr,
                    size_t noise_floats = 0, size_t queue_rows = 64, size_t queue_frames = 16)
      : frames_(queue_frames, 0) {
    status_ = duo_transflower_get_info(model, &info_);  // another family: DUO_INVALID_ARGUMENT
    if (status_ != DUO_OK) return;
    if (config.batched != 0 ||
        (noise_floats > 0 && (noise == nullptr || info_.noise_floats == 0 || noise_floats % info_.noise_floats != 0))) {
      status_ = DUO_INVALID_ARGUMENT;
      return;
    }
    status_ = duo_transflower_session_new(model, &config, seed_motion, seed_floats, labels, n_labels, &session_);
    if (status_ != DUO_OK) return;
    features_ = info_.audio_features;
    if (noise_floats > 0) noise_.assign(noise, noise + noise_floats);
    frames_ = RowRing(queue_frames, info_.channels);
    staged_.assign(info_.channels, 0.0f);
    Start(queue_rows);
  }
  ~TransflowerRunner() override { Stop(); }

  // The model's sizes (zeros for a model of another family).
  const duo_transflower_info& Info() const { return info_; }

  // Game thread: SubmitRows (audio rows).
  size_t SubmitAudio(const float* rows, size_t n_rows) { return SubmitRows(rows, n_rows); }

  // Game thread: moves up to `max` frames (oldest first; Info().channels
  // floats each) into `out` and their indices into `indices` (or NULL);
  // returns how many. Frees room: the worker computes more.
  size_t Take(float* out, uint64_t* indices, size_t max) {
    size_t n = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      for (; n < max && !frames_.Empty(); ++n) frames_.Pop(out + n * info_.channels, indices ? &indices[n] : nullptr);
    }
    if (n) cv_.notify_one();
    return n;
  }

  // Game thread: back to frame 0 (the seed motion, no audio, the base
  // samples reseeded with rng_seed; a noise track replays from its start).
  // Does not wait: the queued rows and the frames not taken are dropped
  // now, a frame in flight when the worker gets to the reset is discarded.
  void Reset(uint64_t rng_seed) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      frames_.Clear();
      ResetLocked(rng_seed);
    }
    cv_.notify_one();
  }

 private:
  duo_result PullFrame() override {
    const size_t nz = info_.noise_floats;
    duo_result r = (next_ + 1) * nz <= noise_.size()
                       ? duo_transflower_pull_frame_with_noise(session_, &noise_[next_ * nz], nz, staged_.data(),
                                                               staged_.size(), &staged_index_)
                       : duo_transflower_pull_frame(session_, staged_.data(), staged_.size(), &staged_index_);
    if (r == DUO_OK) next_ = static_cast<size_t>(staged_index_) + 1;
    return r;
  }
  duo_result ResetSession(uint64_t rng_seed) override {
    next_ = 0;
    return duo_transflower_session_reset(session_, rng_seed);
  }
  bool OutputFull() const override { return frames_.Full(); }
  void StoreFrame() override { frames_.Push(staged_.data(), staged_index_); }

  duo_transflower_info info_{};
  std::vector<float> noise_;   // recorded base samples, noise_floats each
  std::vector<float> staged_;  // worker: the frame being pulled
  uint64_t staged_index_ = 0;
  size_t next_ = 0;            // worker: the next frame's index
  RowRing frames_;             // frames made, not taken (channels floats each)
};

// Owns a Transflower step batch (duo_transflower_step_batch_new): one
// model's step memory that several sessions share, stepped one after
// another by Step (duo_step_batch_step: every frame the one the session
// makes alone, bit for bit). Make the sessions with
// duo_transflower_config.batched = 1 (their state alone; only the batch
// makes their frames, their pulls take them) or 0. Threads: one thread at
// a time, and the sessions of a Step are not used by another thread during
// it; Step runs the model (tens of ms per session at the published size):
// a worker thread, not the game thread. The batch holds a reference on the
// model (the model may be freed first); move-only.
class TransflowerStepBatch {
 public:
  // Check Status() == DUO_OK (DUO_INVALID_ARGUMENT: a model of another family).
  explicit TransflowerStepBatch(const duo_model* model) { status_ = duo_transflower_step_batch_new(model, &batch_); }
  ~TransflowerStepBatch() { duo_step_batch_free(batch_); }
  TransflowerStepBatch(TransflowerStepBatch&& o) noexcept : batch_(o.batch_), status_(o.status_) { o.batch_ = nullptr; }
  TransflowerStepBatch& operator=(TransflowerStepBatch&& o) noexcept {
    std::swap(batch_, o.batch_);
    std::swap(status_, o.status_);
    return *this;
  }
  TransflowerStepBatch(const TransflowerStepBatch&) = delete;
  TransflowerStepBatch& operator=(const TransflowerStepBatch&) = delete;

  duo_result Status() const { return status_; }
  duo_step_batch* Get() const { return batch_; }

  // One step of every session of sessions[0..n] whose audio is in (n <=
  // DUO_MAX_BATCH); *stepped (or NULL) = how many stepped. A refusal
  // (header order) changes nothing: *failed (or NULL) = the session it
  // concerns, else DUO_NO_SESSION. DUO_BACKLOG: that session's
  // pending_frames frames are made and not pulled.
  duo_result Step(duo_session* const* sessions, size_t n, size_t* stepped = nullptr, size_t* failed = nullptr) {
    return duo_step_batch_step(batch_, sessions, n, stepped, failed);
  }

 private:
  duo_step_batch* batch_ = nullptr;
  duo_result status_ = DUO_INTERNAL;
};

}  // namespace duolando
