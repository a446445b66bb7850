/* duolando.h — C ABI of the duolando engine (library `duolando`, crate duolando-ffi).
 *
 * Duolando generates a follower dancer's motion, frame by frame, from a
 * leader's joint positions and music features; a Bailando model (a solo
 * dancer) from music features alone ("Solo models" below). Guide:
 * docs/C_API.md.
 *
 * Objects
 *   duo_model    immutable weights (one .duo file). Opened once, shared by
 *                any number of sessions and threads. Reference counted:
 *                sessions keep their model alive, so models and sessions
 *                may be freed in any order.
 *   duo_session  one dancer (a follower, or a solo dancer on a Bailando
 *                model): streaming state in fixed memory.
 *   duo_step_batch  step memory several sessions of one model share
 *                (Duolando: stepped together, one weight read for all of
 *                them; Transflower: stepped one after another through it).
 *                A Duolando session may be bound to one
 *                (duo_session_new_batched): it then holds its state alone
 *                and keeps the batch alive.
 *
 * Conventions (rustls-ffi style)
 *   - Fallible functions return duo_result. DUO_OK is success; on any
 *     other code (except DUO_NOT_READY, which is not a failure)
 *     duo_last_error_message() tells what went wrong on this thread.
 *   - Output parameters (out_*) are written only when DUO_OK is returned
 *     (failed_session of duo_step_batch_push_leader and
 *     duo_step_batch_step, not an out_ parameter, is written on every
 *     return).
 *   - A NULL required pointer gives DUO_NULL_PARAMETER. Buffers (a pointer
 *     with an element count: bytes/len, memory/len, features/n_features,
 *     track/n_floats, the two pos3d/n_frames, sessions and frames/n)
 *     follow one rule: NULL with count 0 is an empty buffer, answered
 *     exactly as a non-NULL one with count 0 (e.g. a wrong count is
 *     DUO_INVALID_ARGUMENT, empty session memory DUO_BUFFER_TOO_SMALL);
 *     NULL with a count above 0 is DUO_NULL_PARAMETER.
 *     (duo_last_error_message, which returns a length, writes nothing to a
 *     NULL buf whatever len.)
 *   - No function unwinds or aborts on bad input: a bug inside the library
 *     is caught and returned as DUO_PANIC.
 *   - Coordinates are SMPL-X unless a function says otherwise:
 *     right-handed, y up, metres; a dancer at rest faces +z, left side on
 *     +x; 55 joints in SMPL-X order; 30 frames per second.
 *
 * Thread rules are written beside each type and function. */
#ifndef DUOLANDO_H
#define DUOLANDO_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define DUOLANDO_VERSION_MAJOR 0
#define DUOLANDO_VERSION_MINOR 2
#define DUOLANDO_VERSION_PATCH 0

/* Joints per pose (SMPL-X body, jaw, eyes, hands). */
#define DUO_JOINTS 55

/* Joint layouts per family (duo_model_info.family; positions are xyz per
 * joint in this order).
 * Duolando (DUO_JOINTS = 55, SMPL-X): 0 pelvis, 1 left_hip, 2 right_hip,
 *   3 spine1, 4 left_knee, 5 right_knee, 6 spine2, 7 left_ankle,
 *   8 right_ankle, 9 spine3, 10 left_foot, 11 right_foot, 12 neck,
 *   13 left_collar, 14 right_collar, 15 head, 16 left_shoulder,
 *   17 right_shoulder, 18 left_elbow, 19 right_elbow, 20 left_wrist,
 *   21 right_wrist, 22 jaw, 23 left_eye, 24 right_eye, 25-39 left hand
 *   (index1-3, middle1-3, pinky1-3, ring1-3, thumb1-3), 40-54 right hand
 *   (same order).
 * Bailando (DUO_BAILANDO_JOINTS = 24, SMPL, 60 fps): joints 0-21 as above,
 *   22 left_hand, 23 right_hand (solo sessions: "Solo models" below). */
#define DUO_BAILANDO_JOINTS 24

/* ------------------------------------------------------------------ */
/* Results and errors                                                  */
/* ------------------------------------------------------------------ */

/* Result codes. The numbers are stable; codes may be added later: treat
 * any unknown value as a failure. */
typedef enum duo_result {
  /* Success. */
  DUO_OK = 0,
  /* A required pointer argument was NULL. */
  DUO_NULL_PARAMETER = 1,
  /* An argument has a wrong value or size: wrong float count, unknown
   * enum value, seed token outside its vocabulary, model bytes not 64-byte
   * aligned, an invalid session configuration. */
  DUO_INVALID_ARGUMENT = 2,
  /* The bytes or file are not a valid .duo model (the message names the
   * reason: magic, version, truncation, tensor, shape, non-finite scale,
   * a NaN or infinite weight with its tensor's name and element index). */
  DUO_BAD_MODEL = 3,
  /* A caller buffer is too small (session memory). */
  DUO_BUFFER_TOO_SMALL = 4,
  /* No follower frame is ready yet. Not a failure: push more input. */
  DUO_NOT_READY = 5,
  /* An input frame holds NaN, infinity, or a magnitude above the accepted
   * limit (DUO_MAX_POSITION_M, DUO_MAX_MUSIC_FEATURE). The frame was
   * rejected and the session is unchanged. */
  DUO_NON_FINITE_INPUT = 6,
  /* The push was refused because ready follower frames must be pulled
   * first (or the music buffer is full). The session is unchanged. */
  DUO_BACKLOG = 7,
  /* An operating-system call failed: the model file could not be opened
   * or read, or a worker thread could not be started. */
  DUO_IO = 8,
  /* A panic was caught inside the library (a bug: please report it). The
   * object of the call must not be used again, except to free it. */
  DUO_PANIC = 9,
  /* An internal invariant failed (a bug: please report it). */
  DUO_INTERNAL = 10,
  /* The session was told the leader has ended (duo_session_finish): it
   * takes no more leader frames until duo_session_reset. The session is
   * unchanged. */
  DUO_ENDED = 11
} duo_result;

/* The name of a result code ("DUO_OK", ...; "DUO_UNKNOWN" for other
 * numbers): a static string, never NULL, do not free. Thread-safe. */
const char *duo_result_name(int32_t result);

/* Copies this thread's last error message into buf (len bytes) as a
 * NUL-terminated string, truncated to len - 1 bytes at a UTF-8 boundary;
 * nothing is written when buf is NULL or len is 0.
 * Returns the full message length in bytes, not counting the NUL
 * (snprintf convention: a result >= len means it was truncated; call with
 * NULL, 0 to size a buffer). Returns 0 when this thread has no message.
 * The message belongs to the most recent failed call on this thread;
 * successful calls leave it unchanged. Thread-safe (per-thread storage). */
size_t duo_last_error_message(char *buf, size_t len);

/* The library version, e.g. "0.2.0": a static NUL-terminated string.
 * Never NULL; do not free it. Thread-safe. */
const char *duo_version(void);

/* Most threads duo_set_threads accepts. */
#define DUOLANDO_MAX_THREADS 64

/* Splits the large matrix products of every later call (all models and
 * sessions of this process) over `threads` threads: the calling thread
 * plus threads - 1 pooled workers, started on first use of that count.
 * 0 or 1: everything on the calling thread (the default). Outputs do not
 * depend on the thread count (bit-identical). One split product runs at a
 * time: a session stepped on another thread meanwhile computes on its own
 * thread. DUO_INVALID_ARGUMENT above DUOLANDO_MAX_THREADS; DUO_IO when the
 * operating system refuses a thread. Thread-safe. */
duo_result duo_set_threads(uint32_t threads);

/* The thread count set by duo_set_threads (1 when unset). Thread-safe. */
uint32_t duo_get_threads(void);

/* ------------------------------------------------------------------ */
/* Frames and coordinates                                              */
/* ------------------------------------------------------------------ */

typedef struct duo_vec3 {
  float x, y, z;
} duo_vec3;

/* A unit quaternion (x, y, z, w); the library writes w >= 0. */
typedef struct duo_quat {
  float x, y, z, w;
} duo_quat;

/* One leader pose: world joint positions, metres, SMPL-X axes and joint
 * order. 660 bytes, no padding. */
typedef struct duo_leader_frame {
  duo_vec3 joints[DUO_JOINTS];
} duo_leader_frame;

/* One follower pose. 1560 bytes, no padding (offsets: index 0,
 * positions 8, rotations 668, root 1548). */
typedef struct duo_follower_frame {
  /* 0, 1, 2, ... since the session started or was last reset. */
  uint64_t index;
  /* World joint positions in the leader's coordinates (metres). */
  duo_vec3 positions[DUO_JOINTS];
  /* Local joint rotations: joint j relative to its parent (joint 0
   * relative to the world), in SMPL-X rest-pose axes. Each is the nearest
   * proper rotation (SVD projection) of the decoder's raw 3x3 output. */
  duo_quat rotations[DUO_JOINTS];
  /* Root translation: the pelvis (joint 0) world position. */
  duo_vec3 root;
} duo_follower_frame;

/* Coordinate systems for the conversion functions. */
typedef enum duo_coords {
  /* Right-handed, y up, metres, forward +z (the library's own). */
  DUO_COORDS_SMPLX = 0,
  /* Unity: left-handed, y up, metres, forward +z, right +x.
   * p = (-x, y, z); q = (qx, -qy, -qz, qw). */
  DUO_COORDS_UNITY = 1,
  /* Unreal: left-handed, z up, centimetres, forward +x, right +y.
   * p = 100 * (z, -x, y); q = (-qz, qx, -qy, qw). */
  DUO_COORDS_UNREAL = 2
} duo_coords;

/* Position and rotation conversions between SMPL-X and the engines. Each
 * is a change of basis by a reflection P: positions map to P p, rotation
 * matrices to P R P^T (valid for world and for local rotations). These
 * do not retarget: a rig whose bones have non-identity rest orientations
 * still needs its bind pose applied (docs/C_API.md). Pure functions:
 * thread-safe, never fail. */
duo_vec3 duo_vec3_to_unity(duo_vec3 v);
duo_vec3 duo_vec3_from_unity(duo_vec3 v);
duo_quat duo_quat_to_unity(duo_quat q);
duo_quat duo_quat_from_unity(duo_quat q);
duo_vec3 duo_vec3_to_unreal(duo_vec3 v);
duo_vec3 duo_vec3_from_unreal(duo_vec3 v);
duo_quat duo_quat_to_unreal(duo_quat q);
duo_quat duo_quat_from_unreal(duo_quat q);

/* Converts a follower frame in place from SMPL-X to `coords` (a
 * duo_coords value): positions, rotations and root.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (unknown coords). Thread-safe
 * for distinct frames. */
duo_result duo_follower_frame_convert(duo_follower_frame *frame, uint32_t coords);

/* Converts a leader frame in place from `coords` (the system its joints
 * were written in) to SMPL-X, ready to push.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT. Thread-safe for distinct
 * frames. */
duo_result duo_leader_frame_convert(duo_leader_frame *frame, uint32_t coords);

/* ------------------------------------------------------------------ */
/* Model                                                               */
/* ------------------------------------------------------------------ */

/* An opened, validated model. Opaque.
 * Thread rule: immutable; any number of threads may use one model at the
 * same time (open sessions on it, read its info). Only duo_model_free
 * must not race with other calls taking the same handle.
 * Lifetime: reference counted. duo_model_free releases the caller's
 * reference; each session holds its own, so the weights live until the
 * model handle AND every session made from it are freed. */
typedef struct duo_model duo_model;

/* Sizes an engine needs, from duo_model_get_info. */
typedef struct duo_model_info {
  uint32_t joints;           /* joints per pose (55; Bailando 24) */
  uint32_t music_features;   /* floats per music frame (54; Bailando 438) */
  uint32_t fps;              /* frames per second of motion (30; Bailando 60); Duolando's
                                music frames come at this rate, Bailando's music rows
                                one per token (fps / frames_per_token = 7.5 per second) */
  uint32_t frames_per_token; /* motion frames per token (4; Bailando 8) */
  uint32_t block_size;       /* GPT window, tokens (30; Bailando 29) */
  uint32_t look_forward;     /* trained leader/music look-ahead, tokens (29; Bailando 0) */
  uint32_t mapped;           /* 1 if the weights are memory-mapped */
  uint32_t family;           /* DUO_FAMILY_*: the model family (was a reserved 0 before
                                families: 0 is Duolando, so old readers stay right) */
} duo_model_info;

/* Model families (duo_model_info.family; the .duo header's family tag).
 *
 * Solo models (DUO_FAMILY_BAILANDO): a session takes music only and gives
 * joint positions. What differs from a Duolando session:
 *   - seed_tokens are 2 tokens (up, down) instead of 5 (the authors' demo
 *     uses 423, 12 for their model); duo_model_seed_tokens is Duolando's.
 *   - duo_session_config: dec_future, shift, pending_frames,
 *     music_buffer_frames (music ROWS that may wait unread), sampling,
 *     top_k, temperature_milli, kv, rng_seed and staggered (0 or 2: two caches, spread) apply;
 *     lookahead, enc_future, music_lookahead and lat_past must be 0
 *     (DUO_INVALID_ARGUMENT naming the field). Presets: "exact" (the
 *     offline model's numbers), "reference", "interactive", "minimum".
 *   - duo_session_push_music takes one or more whole rows (438 floats
 *     each, one row per token: 7.5 rows per second); a step runs when its
 *     row is there. duo_session_set_music_track copies the rows into the
 *     session (music_buffer_frames must hold them).
 *   - frames come from duo_session_pull_positions (24 joints x 3);
 *     duo_session_push_leader, duo_session_pull_follower and
 *     duo_step_batch_push_leader answer DUO_INVALID_ARGUMENT naming the
 *     family; the session is unchanged.
 *   - duo_session_finish pads the music as the authors' music-only demo
 *     does and runs to its end; the root starts at the origin. */
#define DUO_FAMILY_DUOLANDO 0u
#define DUO_FAMILY_BAILANDO 1u
/* Transflower (.duo family 2): a probabilistic solo dancer. Its frames are
 * the model's motion features (duo_transflower_info.channels floats, in
 * the model's scaled feature space), made from audio feature rows, a
 * motion seed and style labels; see "Transflower sessions" below.
 * duo_model_get_info: joints 0, music_features = floats per audio row,
 * fps 20, frames_per_token 1, block_size = audio rows a step reads,
 * look_forward = audio rows read after a frame's own row. */
#define DUO_FAMILY_TRANSFLOWER 2u

/* Opens a model from caller memory WITHOUT copying.
 * bytes: the whole .duo file, 64-byte aligned in memory (the weights are
 * used in place; misaligned bytes give DUO_INVALID_ARGUMENT: use
 * duo_model_open_copy for arbitrary memory such as a managed byte[]).
 * Ownership: the caller keeps the bytes valid and unmodified until the
 * model and every session made from it are freed.
 * Opening validates the whole file, every f32/f16 weight included (NaN or
 * infinity is refused by tensor name and element index: no model that
 * opens computes NaN from its weights); zero bytes after the data (asset
 * padding) are accepted (docs/FORMAT.md).
 * Results: DUO_OK (*out_model set), DUO_NULL_PARAMETER (out_model, or
 * bytes with len > 0), DUO_INVALID_ARGUMENT (misaligned), DUO_BAD_MODEL
 * (including NULL/0 and truncated input). Thread-safe. */
duo_result duo_model_open_bytes(const uint8_t *bytes, size_t len, duo_model **out_model);

/* Opens a model from caller memory by copying it into a 64-byte aligned
 * buffer owned by the model; bytes may be freed as soon as this returns.
 * Results as duo_model_open_bytes, without the alignment rule. */
duo_result duo_model_open_copy(const uint8_t *bytes, size_t len, duo_model **out_model);

/* Opens a .duo file: memory-mapped read-only (copied instead should the
 * map not be 64-byte aligned). The file must not be modified while the
 * model lives. path: NUL-terminated UTF-8.
 * Results: DUO_OK, DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (path not
 * UTF-8), DUO_IO (cannot open/read; the message has the path and the OS
 * error), DUO_BAD_MODEL. Thread-safe. */
duo_result duo_model_open_file(const char *path, duo_model **out_model);

/* Fills *out_info. DUO_NULL_PARAMETER. Thread-safe. */
duo_result duo_model_get_info(const duo_model *model, duo_model_info *out_info);

/* Releases the caller's reference to the model (the weights go when the
 * last session made from it is freed too). NULL is ignored. Each handle
 * must be freed exactly once and not used afterwards. */
void duo_model_free(duo_model *model);

/* Seed tokens from follower and leader start frames: n_frames frames of
 * 165 floats each (SMPL-X metres), a multiple of frames_per_token is used
 * (at least one token's worth). Allocates temporary memory. Writes 5
 * tokens (up, down, lhand, rhand, transl) to out_tokens.
 * DUO_NULL_PARAMETER (model, out_tokens, or a NULL pos3d with
 * n_frames > 0), DUO_INVALID_ARGUMENT (too few frames, n_frames 0
 * included), DUO_NON_FINITE_INPUT. Thread-safe. */
duo_result duo_model_seed_tokens(const duo_model *model, const float *follower_pos3d,
                                 const float *leader_pos3d, size_t n_frames,
                                 uint32_t *out_tokens);

/* ------------------------------------------------------------------ */
/* Session                                                             */
/* ------------------------------------------------------------------ */

/* One follower dancer: streaming state in fixed memory, allocated once
 * (duo_session_new) or placed in caller memory (duo_session_new_in); no
 * allocation after creation.
 * Thread rule: one thread at a time per session (it may move between
 * threads between calls; no call may overlap another on the same
 * session). Distinct sessions, even on one model, run in parallel.
 * Lifetime: holds a reference to its model (see duo_model). */
typedef struct duo_session duo_session;

/* Accepted input magnitudes: larger values are rejected like NaN. */
#define DUO_MAX_POSITION_M 1.0e4f   /* |leader coordinate|, metres */
#define DUO_MAX_MUSIC_FEATURE 1.0e6f /* |music feature| */

/* duo_session_config.sampling */
typedef enum duo_sampling {
  /* Argmax (lowest token id on ties). Deterministic. */
  DUO_SAMPLING_GREEDY = 0,
  /* Uniform among the top_k most likely tokens; a fixed rng_seed gives a
   * reproducible dance. */
  DUO_SAMPLING_TOP_K = 1,
  /* Among the top_k most likely tokens (1..64), each with its probability
   * under softmax(logits / T), T = temperature_milli / 1000 (1..100000):
   * the likely tokens most of the time (small T: near greedy; 1000: the
   * model's own distribution). One draw per token, the same bits on every
   * CPU; a fixed rng_seed gives a reproducible dance. */
  DUO_SAMPLING_SOFTMAX = 2
} duo_sampling;

/* duo_session_config.kv: element type of the session's keys and values
 * (the GPT cache and the LAT rings). */
typedef enum duo_kv {
  DUO_KV_F32 = 0,
  /* Half the K/V bytes; tokens may rarely differ from f32. */
  DUO_KV_F16 = 1
} duo_kv;

/* The latency budget and buffers of a session. Start from
 * duo_session_config_reference or _minimum and change fields. Counts are
 * tokens (4 frames) unless named frames. 64 bytes, no padding (56 before
 * DUO_SAMPLING_SOFTMAX: rebuild hosts against this header). */
typedef struct duo_session_config {
  uint32_t lookahead;           /* leader look-ahead, 0..look_forward */
  uint32_t enc_future;          /* encoder future context */
  uint32_t dec_future;          /* decoder future context */
  uint32_t shift;               /* GPT window chunk shift, 1..block_size-1 */
  uint32_t music_lookahead;     /* music look-ahead, 0..look_forward */
  uint32_t lat_past;            /* past band of the look-ahead transformers */
  uint32_t pending_frames;      /* leader frames pushed and not yet pulled
                                   as follower frames, beyond latency + 1,
                                   before DUO_BACKLOG */
  uint32_t music_buffer_frames; /* music frames that may wait before
                                   DUO_BACKLOG */
  uint32_t sampling;            /* a duo_sampling value */
  uint32_t top_k;               /* for DUO_SAMPLING_TOP_K and _SOFTMAX */
  uint32_t staggered;           /* 2 (every preset): two caches, the next
                                   window filled a few rows per step (a flat
                                   cost per step after the first jump); 0:
                                   one GPT cache, re-filled when the window
                                   jumps (least memory, a cost spike every
                                   chunk: most of an R step); 1: one cache
                                   per live window (flat cost, more memory).
                                   Same output. */
  uint32_t kv;                  /* a duo_kv value */
  uint64_t rng_seed;            /* for DUO_SAMPLING_TOP_K and _SOFTMAX */
  uint32_t temperature_milli;   /* for DUO_SAMPLING_SOFTMAX: the temperature
                                   in thousandths, 1..100000 (ignored by the
                                   other rules) */
  uint32_t reserved;            /* 0 (DUO_INVALID_ARGUMENT otherwise) */
} duo_session_config;

/* The full look-ahead and conv context (R's leader codes and frames; long
 * latency: about 9.7 s for the full model) and the presets' window shift,
 * the largest whose step computes at most two GPT rows (15 for the full
 * model; 22 until 2026-12-07: closer to the offline model, twice the GPT
 * work a step; set `shift` for it). DUO_NULL_PARAMETER. Thread-safe. */
duo_result duo_session_config_reference(const duo_model *model, duo_session_config *out_config);

/* The named preset `name` (NUL-terminated; the list `duolando inspect`
 * shows and `--preset` takes): "reference", "interactive" (leader
 * look-ahead 4, enc/dec future 2: 31 frames), "live-music" (interactive
 * with music_lookahead 0: music pushed in lockstep with the leader),
 * "minimum". DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (no such preset).
 * Thread-safe. */
duo_result duo_session_config_preset(const duo_model *model, const char *name, duo_session_config *out_config);

/* The lowest-latency configuration: no leader look-ahead, no encoder or
 * decoder future context (latency 0 frames), music look-ahead kept.
 * DUO_NULL_PARAMETER. Thread-safe. */
duo_result duo_session_config_minimum(const duo_model *model, duo_session_config *out_config);

/* Bytes duo_session_new_in needs for this configuration, for memory at any
 * address. DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (a setting out of
 * range; the message names it). Thread-safe. */
duo_result duo_session_bytes(const duo_model *model, const duo_session_config *config,
                             size_t *out_bytes);

/* Creates a session in library memory (one allocation, here).
 * seed_tokens: 5 follower start tokens (up, down, lhand, rhand, transl),
 * e.g. from duo_model_seed_tokens; 2 (up, down) for a solo model.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (config or seed token out of
 * range). Thread-safe (takes a reference on the model). */
duo_result duo_session_new(const duo_model *model, const duo_session_config *config,
                           const uint32_t *seed_tokens, duo_session **out_session);

/* Creates a session entirely inside caller memory: `memory` (any
 * alignment), `len` >= duo_session_bytes(). No allocation. The memory
 * must stay valid, unmoved and untouched until duo_session_free; free it
 * yourself afterwards. DUO_BUFFER_TOO_SMALL (NULL/0 included),
 * DUO_NULL_PARAMETER (memory NULL with len > 0), and as duo_session_new. */
duo_result duo_session_new_in(const duo_model *model, const duo_session_config *config,
                              const uint32_t *seed_tokens, void *memory, size_t len,
                              duo_session **out_session);

/* *out_frames = delay in frames between a leader frame and the follower
 * frame of the same index: every follower frame f is ready once leader
 * frame f + *out_frames is pushed. With a track (duo_session_set_music_track)
 * max(0, 4 (lookahead + enc_future + dec_future) - 1); otherwise, for music
 * pushed exactly music_lookahead tokens ahead (music frame f + 4
 * music_lookahead in before leader frame f; lockstep for 0), at least
 * 4 (dec_future + 1) - 1: the music of a step is that of the next token
 * (the model reads music from frame 4), so with lookahead + enc_future = 0
 * the music, not the leader, sets the delay. DUO_NULL_PARAMETER. */
duo_result duo_session_latency_frames(const duo_session *session, uint32_t *out_frames);

/* Gives the session a whole music track known in advance: frames x
 * music_features floats (30 fps), BORROWED: keep it valid and unmodified
 * until the session is reset or freed. Use instead of
 * duo_session_push_music, before any music frame is pushed. An empty
 * track (NULL or not, n_floats 0) is a track of 0 frames: accepted, and
 * music is then given.
 * DUO_NULL_PARAMETER (session, or track NULL with n_floats > 0),
 * DUO_INVALID_ARGUMENT (not whole frames; music already given),
 * DUO_NON_FINITE_INPUT. */
duo_result duo_session_set_music_track(duo_session *session, const float *track, size_t n_floats);

/* Pushes one music feature frame (n_features = music_features floats,
 * copied). Push music at least music_lookahead tokens ahead of the leader
 * for the latency of duo_session_latency_frames. At most
 * music_buffer_frames frames are held (pushed, not yet read by the model;
 * the first 4 of a session count until it starts reading).
 * DUO_NULL_PARAMETER (session, or features NULL with n_features > 0),
 * DUO_INVALID_ARGUMENT (wrong count, 0 included; a track was given),
 * DUO_NON_FINITE_INPUT and DUO_BACKLOG (music buffer full: push leader
 * frames first); both leave the session unchanged. */
duo_result duo_session_push_music(duo_session *session, const float *features, size_t n_features);

/* Pushes one leader frame (copied). May run one model step (the costly
 * call: run it off the render thread).
 * DUO_NON_FINITE_INPUT: NaN, infinity, or |value| > DUO_MAX_POSITION_M;
 *   the frame is rejected and the session is unchanged. To keep the
 *   30 fps clock, push your last good frame instead.
 * DUO_BACKLOG: the leader frames pushed minus the follower frames pulled
 *   reach latency + 1 + pending_frames (pull ready frames first), or the
 *   music is too far behind; session unchanged.
 * DUO_ENDED: after duo_session_finish (until duo_session_reset).
 * DUO_NULL_PARAMETER. */
duo_result duo_session_push_leader(duo_session *session, const duo_leader_frame *frame);

/* The leader has ended: the session decodes what its look-ahead allows,
 * as the offline model does at the end of a clip (docs/STREAMING.md §2
 * "Drain"); pull the remaining frames as usual: with T leader frames,
 * 4 (K + 1) frames in all, K = (T - T % 4 - 4) / 4 - 29 (the offline
 * model's count; more if music_lookahead < 29 already ran further).
 * Steps still wait for their music: push it up to the leader's end if it
 * is not a track. Afterwards duo_session_push_leader answers DUO_ENDED
 * (session unchanged) until duo_session_reset; music may still be pushed;
 * calling it again does nothing. DUO_NULL_PARAMETER. */
duo_result duo_session_finish(duo_session *session);

/* Pulls the next follower frame: DUO_OK (*out_frame written) or
 * DUO_NOT_READY (nothing ready; *out_frame untouched). Frame f becomes
 * ready once leader frame f + latency has been pushed. Pull in a loop
 * after each push until DUO_NOT_READY. DUO_NULL_PARAMETER;
 * DUO_INVALID_ARGUMENT on a solo model's session. */
duo_result duo_session_pull_follower(duo_session *session, duo_follower_frame *out_frame);

/* Pulls the next frame's world joint positions (metres), for a session of
 * any family: n_floats = duo_model_info.joints x 3 (165; Bailando 72).
 * DUO_OK (out and *out_index written; out_index may be NULL) or
 * DUO_NOT_READY (nothing written). A solo session with its music in runs
 * the steps a frame needs here (the costly call: off the render thread).
 * DUO_NULL_PARAMETER (session, out), DUO_INVALID_ARGUMENT (n_floats). */
duo_result duo_session_pull_positions(duo_session *session, float *out, size_t n_floats,
                                      uint64_t *out_index);

/* Back to the start (frame index 0) with new seed tokens (5, or 2 for a
 * solo model); the music track is dropped. No allocation. DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT. */
duo_result duo_session_reset(duo_session *session, const uint32_t *seed_tokens);

/* Frees a session and drops its model reference. NULL is ignored. For a
 * session made by duo_session_new_in, release the memory afterwards. Each
 * session must be freed exactly once and not used afterwards. */
void duo_session_free(duo_session *session);

/* ------------------------------------------------------------------ */
/* Transflower sessions                                                */
/* ------------------------------------------------------------------ */

/* A Transflower session (a duo_session): frame t is song row
 * output_time_offset + t; its step reads audio rows t .. t + audio_window - 1
 * (pushed with duo_session_push_music: one or more whole rows of
 * audio_features floats, at most input_buffer_rows beyond the window held,
 * else DUO_BACKLOG) and the session's own motion so far (the seed, then its
 * frames). Base samples come from the session's seeded RNG
 * (duo_transflower_pull_frame: a given rng_seed gives the same dance) or
 * from the caller (duo_transflower_pull_frame_with_noise). With refresh 1
 * the frames are the offline model's (R mode) bit for bit; refresh k > 1
 * recomputes every row only every k-th step and in between only the newest
 * and conditioning rows (faster, approximate: docs/TRANSFLOWER.md "S
 * mode"). duo_session_push_music and duo_session_free apply; the other
 * duo_session_* calls answer DUO_INVALID_ARGUMENT naming the family.
 * Several sessions of one model may share one step's memory: a
 * duo_step_batch ("Sessions stepped together" below). */

/* Sizes of a Transflower model. 48 bytes. */
typedef struct duo_transflower_info {
  uint32_t channels;           /* floats per frame */
  uint32_t seed_rows;          /* rows of the motion seed (seed_rows x channels floats) */
  uint32_t inputs;             /* input modalities (motion, audio, labels) */
  uint32_t audio_features;     /* floats per audio row (duo_session_push_music) */
  uint32_t audio_window;       /* audio rows a step reads */
  uint32_t labels;             /* style labels a session takes */
  uint32_t label_values;       /* values of the first style label (0 if none) */
  uint32_t noise_floats;       /* floats of one base sample (channels x frames per sample) */
  uint32_t fps;                /* frames per second (20) */
  uint32_t output_time_offset; /* frame t is song row output_time_offset + t */
  int32_t lookahead_rows;      /* audio rows after a frame's own row its step reads (19: 0.95 s) */
  uint32_t reserved;
} duo_transflower_info;

/* A Transflower session's settings. 32 bytes. */
typedef struct duo_transflower_config {
  uint32_t refresh;           /* steps between recomputations of every row, 1..4096 (1: R) */
  uint32_t kv;                /* a duo_kv value: the kept keys and values (refresh > 1) */
  uint32_t input_buffer_rows; /* audio rows held beyond the window, 0..65536 */
  uint32_t pending_frames;    /* frames made and not pulled, 1..65536 */
  uint32_t rolling;           /* 1: a share of the rows recomputed every step (a flat cost);
                                 0: all of them every refresh-th step (a spike) */
  uint32_t batched;           /* 0: the session has its own step memory (its pulls step
                                 it; a batch may step it too). 1: for step batches only:
                                 its state alone (duo_transflower_session_bytes gives the
                                 smaller size); only duo_step_batch_step makes its frames,
                                 its pulls take them (DUO_NOT_READY until one is made).
                                 Was `reserved` (0) before step batches. */
  uint64_t rng_seed;          /* the base samples' seed */
} duo_transflower_config;

/* DUO_NULL_PARAMETER; DUO_INVALID_ARGUMENT on a model of another family.
 * Thread-safe. */
duo_result duo_transflower_get_info(const duo_model *model, duo_transflower_info *out_info);

/* The named preset: "exact" (refresh 1), "reference" (4, f32, all rows
 * every 4th step), "realtime" (16, f16, rolling); rng_seed 0. DUO_NULL_PARAMETER,
 * DUO_INVALID_ARGUMENT (no such preset, another family). Thread-safe. */
duo_result duo_transflower_config_preset(const duo_model *model, const char *name,
                                         duo_transflower_config *out_config);

/* Bytes duo_transflower_session_new_in needs for `config`, for memory at
 * any address (duo_transflower_session_new allocates about as much, once);
 * with config->batched = 1 the state alone, without a step's memory.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (a setting out of range: the
 * message names it). Thread-safe. */
duo_result duo_transflower_session_bytes(const duo_model *model, const duo_transflower_config *config,
                                         size_t *out_bytes);

/* Creates a session: seed_motion = seed_rows x channels floats (the scaled
 * motion features before the first frame), labels = `labels` values (one
 * per style input, each below label_values; NULL with 0 when none).
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (counts, settings, a label out
 * of range, another family), DUO_NON_FINITE_INPUT. Thread-safe. */
duo_result duo_transflower_session_new(const duo_model *model, const duo_transflower_config *config,
                                       const float *seed_motion, size_t n_floats,
                                       const uint32_t *labels, size_t n_labels,
                                       duo_session **out_session);

/* As duo_transflower_session_new, with the session placed entirely in
 * caller memory (`memory`, len >= duo_transflower_session_bytes, any
 * alignment; it must stay valid, unmoved and untouched until
 * duo_session_free, after which it may be released): no allocation.
 * Also DUO_BUFFER_TOO_SMALL (len short: the message gives the size). */
duo_result duo_transflower_session_new_in(const duo_model *model, const duo_transflower_config *config,
                                          const float *seed_motion, size_t n_floats,
                                          const uint32_t *labels, size_t n_labels, void *memory,
                                          size_t len, duo_session **out_session);

/* Rows of sliding input `index` for models with more than one (the audio,
 * the last input, also takes duo_session_push_music). DUO_NULL_PARAMETER,
 * DUO_INVALID_ARGUMENT (the motion or a label, not whole rows, n 0),
 * DUO_NON_FINITE_INPUT, DUO_BACKLOG; each leaves the session unchanged. */
duo_result duo_transflower_push_input(duo_session *session, uint32_t index, const float *rows,
                                      size_t n_floats);

/* The next frame (n_floats = channels): DUO_OK (out and *out_index
 * written; out_index may be NULL) or DUO_NOT_READY (its audio is not in
 * yet; nothing written). Runs the frame's step (the costly call: off the
 * render thread) with the session's seeded base sample, unless a frame was
 * already made by duo_step_batch_step (then it takes that one). A batched
 * session (config.batched = 1) never steps here: DUO_NOT_READY until its
 * batch has made a frame.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (n_floats, another family). */
duo_result duo_transflower_pull_frame(duo_session *session, float *out, size_t n_floats,
                                      uint64_t *out_index);

/* As duo_transflower_pull_frame with the caller's base sample: noise =
 * noise_floats floats, channel-major (channels x frames per sample), e.g.
 * recorded noise to replay a dance; the RNG is not drawn.
 * DUO_NON_FINITE_INPUT (noise), and as duo_transflower_pull_frame. */
duo_result duo_transflower_pull_frame_with_noise(duo_session *session, const float *noise,
                                                 size_t n_noise, float *out, size_t n_floats,
                                                 uint64_t *out_index);

/* Back to frame 0: the seed motion, no audio, the RNG reseeded.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (another family). */
duo_result duo_transflower_session_reset(duo_session *session, uint64_t rng_seed);

/* ------------------------------------------------------------------ */
/* Sessions stepped together                                           */
/* ------------------------------------------------------------------ */

/* Step memory several sessions of one model share. One handle for the
 * families that have one; each family makes it with its own constructor,
 * steps it with its own call, and frees it with duo_step_batch_free:
 *   - Duolando (duo_step_batch_new; duo_step_batch_push_leader): scratch
 *     for stepping sessions TOGETHER, each weight matrix of the heavy part
 *     of a step read once for all of them (16 sessions of the full model
 *     take 4.4-4.6x the time of one, not 16x). Every session ends exactly
 *     as after its own duo_session_push_leader, bit for bit. Such a batch
 *     holds no session state and no model reference: it is sized for a
 *     configuration and a number of sessions, and steps any sessions of
 *     one model whose configurations need no more than that one.
 *   - Transflower (duo_transflower_step_batch_new; duo_step_batch_step):
 *     one model's step scratch and flow weights, the sessions stepped ONE
 *     AFTER ANOTHER through it, so that they need not each hold a step's
 *     memory (a session made with duo_transflower_config.batched = 1 holds
 *     its state alone). Every frame is the one the session makes stepped
 *     alone (duo_transflower_pull_frame with its seeded RNG), bit for bit.
 *     The size depends on the model only (not on the sessions' configs or
 *     number). Holds a reference on its model, as a session does.
 * A batch of one family refuses the other family's call and sessions
 * (DUO_INVALID_ARGUMENT naming both families).
 * Thread rule: one thread at a time; the sessions of a call must not be
 * used by another thread during it. (The calls of sessions bound to a
 * Duolando batch, below, may come from other threads: they take the
 * batch's lock.)
 *
 * The refusals of duo_step_batch_push_leader and duo_step_batch_step, in
 * this one order; the first refusal answers, before any session changes,
 * *failed_session naming the session concerned:
 *   1. the call (DUO_NO_SESSION): batch NULL (DUO_NULL_PARAMETER), or of
 *      the other family (DUO_INVALID_ARGUMENT); n == 0 does nothing
 *      (DUO_OK, sessions and frames may be NULL; *out_stepped = 0); n
 *      above the batch's max_sessions (DUO_MAX_BATCH for a Transflower
 *      batch) (DUO_INVALID_ARGUMENT); sessions NULL, then frames NULL
 *      (DUO_NULL_PARAMETER);
 *   2. each session, by index: NULL (DUO_NULL_PARAMETER); given twice, of
 *      another family than the batch's, of another model than sessions[0]
 *      (Duolando) or than the batch's (Transflower), or with a
 *      configuration that needs more than the batch's (Duolando)
 *      (DUO_INVALID_ARGUMENT);
 *   3. each frame, by index (push_leader): NaN, infinity or |value| >
 *      DUO_MAX_POSITION_M (DUO_NON_FINITE_INPUT);
 *   4. each session, by index: it would refuse its step for backlog
 *      (DUO_BACKLOG: push_leader as duo_session_push_leader; step: its
 *      pending_frames frames are made and not pulled).
 * So a session of another model at index 4 is reported before a bad frame
 * at index 0, and a bad frame at index 3 before a backlogged session 1.
 * failed_session (NULL or writable) is written on EVERY return: the index
 * of the session a failure concerns, else DUO_NO_SESSION. */
typedef struct duo_step_batch duo_step_batch;

/* Most sessions one batch steps (per call). */
#define DUO_MAX_BATCH 64
/* failed_session of a call that succeeded or whose failure concerns no
 * single session. */
#define DUO_NO_SESSION ((size_t)-1)

/* Bytes duo_step_batch_new_in needs for max_sessions (1..DUO_MAX_BATCH)
 * sessions of this configuration, for memory at any address.
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT. Thread-safe. */
duo_result duo_step_batch_bytes(const duo_model *model, const duo_session_config *config,
                                size_t max_sessions, size_t *out_bytes);

/* Creates a Duolando batch in library memory (one allocation, here).
 * DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (another family's model too).
 * Thread-safe. */
duo_result duo_step_batch_new(const duo_model *model, const duo_session_config *config,
                              size_t max_sessions, duo_step_batch **out_batch);

/* Creates a Duolando batch entirely inside caller memory: `memory` (any
 * alignment), `len` >= duo_step_batch_bytes(). No allocation. The memory
 * must stay valid, unmoved and untouched until duo_step_batch_free.
 * DUO_BUFFER_TOO_SMALL (NULL/0 included), DUO_NULL_PARAMETER (memory NULL
 * with len > 0), and as duo_step_batch_new. */
duo_result duo_step_batch_new_in(const duo_model *model, const duo_session_config *config,
                                 size_t max_sessions, void *memory, size_t len,
                                 duo_step_batch **out_batch);

/* Duolando batch: pushes frames[i] into sessions[i] for every i < n and
 * runs the steps that become possible, the sessions together (the costly
 * call: run it off the render thread). Pull each session's frames
 * afterwards as usual. Refusals: the order above. */
duo_result duo_step_batch_push_leader(duo_step_batch *batch, duo_session *const *sessions,
                                      const duo_leader_frame *frames, size_t n,
                                      size_t *failed_session);

/* Bytes duo_transflower_step_batch_new_in needs for `model` (any
 * address): the model's step scratch and reverse flow weights, the same
 * for any number of sessions of any configuration (docs/C_API.md gives
 * the published size). DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (another
 * family's model). Thread-safe. */
duo_result duo_transflower_step_batch_bytes(const duo_model *model, size_t *out_bytes);

/* Creates a Transflower batch in library memory (one allocation, here);
 * it steps the sessions of `model` of every configuration, batched or
 * not. DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (another family's model).
 * Thread-safe (takes a reference on the model). */
duo_result duo_transflower_step_batch_new(const duo_model *model, duo_step_batch **out_batch);

/* As duo_transflower_step_batch_new, entirely inside caller memory
 * (`memory`, any alignment, len >= duo_transflower_step_batch_bytes; it
 * must stay valid, unmoved and untouched until duo_step_batch_free): no
 * allocation. Also DUO_BUFFER_TOO_SMALL (NULL/0 included) and
 * DUO_NULL_PARAMETER (memory NULL with len > 0). */
duo_result duo_transflower_step_batch_new_in(const duo_model *model, void *memory, size_t len,
                                             duo_step_batch **out_batch);

/* Transflower batch: steps every session of sessions[0..n] whose audio is
 * in once, one after another (the costly call: off the render thread),
 * each with its own seeded RNG; a session without its audio is skipped.
 * Each step makes one frame, kept for the session's pulls
 * (duo_transflower_pull_frame takes it without stepping). On DUO_OK
 * *out_stepped (may be NULL) = the sessions stepped (0 when none had its
 * audio). Refusals: the order above. */
duo_result duo_step_batch_step(duo_step_batch *batch, duo_session *const *sessions, size_t n,
                               size_t *out_stepped, size_t *failed_session);

/* Frees a batch of either family; its sessions are untouched (a
 * Transflower batch drops its model reference). NULL is ignored. Sessions
 * bound to a Duolando batch (below) keep it: it goes with the last of
 * them. For a batch made in caller memory (_new_in), release the memory
 * once the batch and the sessions bound to it are freed. */
void duo_step_batch_free(duo_step_batch *batch);

/* Duolando sessions bound to a batch: a session that holds its state alone
 * (the full model with f16 K/V, one GPT cache: 15,994,815 bytes + the
 * handle, 1.5 MB less than duo_session_bytes) and borrows the step memory
 * of its Duolando batch for every call that runs the model: its creation,
 * duo_session_push_leader, _push_music, _set_music_track, _finish,
 * _pull_follower / _pull_positions (a finished session steps in its
 * pulls) and _reset. duo_step_batch_push_leader steps it with the batch it
 * is given, as any session. Its frames are those of a session made by
 * duo_session_new, bit for bit. The batch's step memory is behind a lock:
 * sessions bound to one batch may be used on different threads (one
 * thread per session, as always), their calls then running one at a time.
 * A bound session holds a reference on its batch, as on its model. */

/* Bytes duo_session_new_batched_in needs for `config` (any address): the
 * state alone. DUO_NULL_PARAMETER, DUO_INVALID_ARGUMENT (a setting out of
 * range; a model of another family). Thread-safe. */
duo_result duo_session_batched_bytes(const duo_model *model, const duo_session_config *config,
                                     size_t *out_bytes);

/* A session bound to `batch` (a Duolando batch whose configuration needs at
 * least the step memory `config` needs), in library memory (one
 * allocation, here). Refusals in this order: model NULL, a model of another
 * family, config NULL or a setting out of range, seed_tokens NULL, batch
 * NULL or of another family or holding less step memory than `config`
 * needs (made for a smaller configuration or another model), out_session
 * NULL, a seed token outside its vocabulary. Thread-safe for the model;
 * the batch's lock is taken for the seed's decoding. */
duo_result duo_session_new_batched(const duo_model *model, const duo_session_config *config,
                                   const uint32_t *seed_tokens, duo_step_batch *batch,
                                   duo_session **out_session);

/* As duo_session_new_batched, entirely inside caller memory: `memory` (any
 * alignment), `len` >= duo_session_batched_bytes(); it must stay valid,
 * unmoved and untouched until duo_session_free. No allocation. Also
 * DUO_BUFFER_TOO_SMALL (NULL/0 included) and DUO_NULL_PARAMETER (memory
 * NULL with len > 0). */
duo_result duo_session_new_batched_in(const duo_model *model, const duo_session_config *config,
                                      const uint32_t *seed_tokens, duo_step_batch *batch,
                                      void *memory, size_t len, duo_session **out_session);

#ifdef __cplusplus
}
#endif

#endif /* DUOLANDO_H */
