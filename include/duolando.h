/* duolando.h — C ABI of the duolando engine (library `duolando`, crate duolando-ffi).
 *
 * Duolando generates a follower dancer's motion, frame by frame, from a
 * leader's joint positions and music features. Guide: docs/C_API.md.
 *
 * Objects
 *   duo_model    immutable weights (one .duo file). Opened once, shared by
 *                any number of sessions and threads. Reference counted:
 *                sessions keep their model alive, so models and sessions
 *                may be freed in any order.
 *   duo_session  one follower dancer: streaming state in fixed memory.
 *
 * Conventions (rustls-ffi style)
 *   - Fallible functions return duo_result. DUO_OK is success; on any
 *     other code (except DUO_NOT_READY, which is not a failure)
 *     duo_last_error_message() tells what went wrong on this thread.
 *   - Output parameters (out_*) are written only when DUO_OK is returned.
 *   - A NULL required pointer gives DUO_NULL_PARAMETER. A NULL buffer with
 *     length 0 is accepted as empty where a buffer is taken.
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
#define DUOLANDO_VERSION_MINOR 1
#define DUOLANDO_VERSION_PATCH 0

/* Joints per pose (SMPL-X body, jaw, eyes, hands). */
#define DUO_JOINTS 55

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
   * reason: magic, version, truncation, tensor, shape, non-finite scale). */
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
  /* The model file could not be opened or read. */
  DUO_IO = 8,
  /* A panic was caught inside the library (a bug: please report it). The
   * object of the call must not be used again, except to free it. */
  DUO_PANIC = 9,
  /* An internal invariant failed (a bug: please report it). */
  DUO_INTERNAL = 10
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

/* The library version, e.g. "0.1.0": a static NUL-terminated string.
 * Never NULL; do not free it. Thread-safe. */
const char *duo_version(void);

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

/* Sizes an engine needs, from duo_model_info. */
typedef struct duo_model_info {
  uint32_t joints;           /* joints per pose (55) */
  uint32_t music_features;   /* floats per music frame (54) */
  uint32_t fps;              /* frames per second of motion and music (30) */
  uint32_t frames_per_token; /* motion frames per token (4) */
  uint32_t block_size;       /* GPT window, tokens (30) */
  uint32_t look_forward;     /* trained leader/music look-ahead, tokens (29) */
  uint32_t mapped;           /* 1 if the weights are memory-mapped */
  uint32_t reserved;         /* 0 */
} duo_model_info;

/* Opens a model from caller memory WITHOUT copying.
 * bytes: the whole .duo file, 64-byte aligned in memory (the weights are
 * used in place; misaligned bytes give DUO_INVALID_ARGUMENT: use
 * duo_model_open_copy for arbitrary memory such as a managed byte[]).
 * Ownership: the caller keeps the bytes valid and unmodified until the
 * model and every session made from it are freed.
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
duo_result duo_model_info(const duo_model *model, duo_model_info *out_info);

/* Releases the caller's reference to the model (the weights go when the
 * last session made from it is freed too). NULL is ignored. Each handle
 * must be freed exactly once and not used afterwards. */
void duo_model_free(duo_model *model);

#ifdef __cplusplus
}
#endif

#endif /* DUOLANDO_H */
