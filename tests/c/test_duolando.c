/* C host test of include/duolando.h, linked against the static and the
 * dynamic library and run under valgrind by .ci/ffi.sh.
 *
 * Opens the fixture model (tests/fixtures/tiny/model.duo) from a file,
 * from aligned memory and by copy; runs sessions in library memory and in
 * caller memory, on 4 threads sharing one model; feeds bad input (NULL
 * pointers, wrong sizes, truncated and misaligned models, NaN/Inf/huge
 * frames, bad configs and seeds) and checks every result code; checks that
 * rejected frames leave a session unchanged, that outputs are finite and
 * deterministic, and that outputs are written only on success.
 *
 * usage: test_duolando <repo root> */
#define _POSIX_C_SOURCE 200112L
#include "duolando.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond)                                                        \
  do {                                                                     \
    if (!(cond)) {                                                         \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__,     \
              #cond);                                                      \
      failures++;                                                          \
    }                                                                      \
  } while (0)

/* Checks that `call` returns `want`; prints the last error otherwise. */
#define EXPECT(call, want)                                                 \
  do {                                                                     \
    duo_result got_ = (call);                                              \
    if (got_ != (want)) {                                                  \
      char msg_[512];                                                      \
      duo_last_error_message(msg_, sizeof msg_);                           \
      fprintf(stderr, "%s:%d: %s returned %s, expected %s (%s)\n",         \
              __FILE__, __LINE__, #call, duo_result_name(got_),            \
              duo_result_name(want), msg_);                                \
      failures++;                                                          \
    }                                                                      \
  } while (0)

/* ---- fixture input ---------------------------------------------------- */

static unsigned char *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  unsigned char *buf;
  long n;
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  n = ftell(f);
  fseek(f, 0, SEEK_SET);
  buf = (unsigned char *)malloc((size_t)n + 1);
  if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
    free(buf);
    buf = NULL;
  }
  fclose(f);
  *len = (size_t)n;
  return buf;
}

/* A little-endian float32 .npy file (version 1): the data and its size. */
static float *read_npy_f32(const char *path, size_t *n_floats) {
  size_t len = 0, header;
  unsigned char *raw = read_file(path, &len);
  float *data;
  if (!raw || len < 10 || memcmp(raw, "\x93NUMPY", 6) != 0) {
    free(raw);
    return NULL;
  }
  header = 10 + (size_t)raw[8] + 256u * (size_t)raw[9];
  if (!strstr((const char *)raw + 10, "'<f4'") || header > len) {
    free(raw);
    return NULL;
  }
  *n_floats = (len - header) / 4;
  data = (float *)malloc(*n_floats * sizeof(float));
  memcpy(data, raw + header, *n_floats * sizeof(float));
  free(raw);
  return data;
}

static char root_dir[1024];
static char model_path[1100];
static duo_leader_frame *leader = NULL; /* (n_frames) */
static size_t n_frames = 0;
static float *music = NULL; /* (n_frames, 54) */
static size_t n_music_floats = 0;
static const uint32_t seed[5] = {1, 2, 3, 4, 5};

static int load_inputs(void) {
  char path[1200];
  size_t n = 0, i;
  float *pos;
  sprintf(path, "%s/tests/fixtures/rollout_tiny_odd/leader_pos3d.npy", root_dir);
  pos = read_npy_f32(path, &n);
  if (!pos) return 0;
  n_frames = n / 165 / 4 * 4;
  leader = (duo_leader_frame *)malloc(n_frames * sizeof(duo_leader_frame));
  for (i = 0; i < n_frames; i++) memcpy(&leader[i], pos + i * 165, sizeof(duo_leader_frame));
  free(pos);
  sprintf(path, "%s/tests/fixtures/rollout_tiny_odd/music.npy", root_dir);
  music = read_npy_f32(path, &n_music_floats);
  return music != NULL && n_music_floats >= n_frames * 54;
}

static int frame_finite(const duo_follower_frame *f) {
  int j;
  for (j = 0; j < DUO_JOINTS; j++) {
    const duo_vec3 *p = &f->positions[j];
    const duo_quat *q = &f->rotations[j];
    float n2 = q->x * q->x + q->y * q->y + q->z * q->z + q->w * q->w;
    if (!isfinite(p->x) || !isfinite(p->y) || !isfinite(p->z)) return 0;
    if (!(fabsf(n2 - 1.0f) < 1e-4f)) return 0;
  }
  return isfinite(f->root.x) && isfinite(f->root.y) && isfinite(f->root.z);
}

/* ---- a run ------------------------------------------------------------ */

/* Pushes every leader frame (music as a track), pulling after each push;
 * before every 5th frame (when `noise`) pushes a bad frame that must be
 * rejected. Returns the number of frames written to out (<= cap). */
static size_t drive(duo_session *s, duo_follower_frame *out, size_t cap, int noise) {
  size_t i, got = 0;
  duo_follower_frame f;
  EXPECT(duo_session_set_music_track(s, music, n_frames * 54), DUO_OK);
  for (i = 0; i < n_frames; i++) {
    duo_result r;
    if (noise && i % 5 == 2) {
      duo_leader_frame bad = leader[i];
      float v[3];
      v[0] = (float)NAN;
      v[1] = (float)INFINITY;
      v[2] = 1e9f;
      bad.joints[i % DUO_JOINTS].z = v[i % 3];
      EXPECT(duo_session_push_leader(s, &bad), DUO_NON_FINITE_INPUT);
    }
    r = duo_session_push_leader(s, &leader[i]);
    /* The music track ends: past its last step no frame comes out, the
     * leader frames pile up, and the session refuses more. */
    if (r == DUO_BACKLOG) break;
    CHECK(r == DUO_OK);
    while ((r = duo_session_pull_follower(s, &f)) == DUO_OK) {
      CHECK(f.index == got);
      CHECK(frame_finite(&f));
      if (got < cap) out[got] = f;
      got++;
    }
    CHECK(r == DUO_NOT_READY);
  }
  return got;
}

/* ---- tests ------------------------------------------------------------ */

static void test_errors_and_version(void) {
  char buf[8];
  size_t n;
  CHECK(strcmp(duo_version(), "0.2.0") == 0);
  CHECK(duo_get_threads() == 1);
  EXPECT(duo_set_threads(2), DUO_OK);
  CHECK(duo_get_threads() == 2);
  EXPECT(duo_set_threads(DUOLANDO_MAX_THREADS + 1), DUO_INVALID_ARGUMENT);
  EXPECT(duo_set_threads(1), DUO_OK);
  CHECK(strcmp(duo_result_name(DUO_OK), "DUO_OK") == 0);
  CHECK(strcmp(duo_result_name(DUO_PANIC), "DUO_PANIC") == 0);
  CHECK(strcmp(duo_result_name(-5), "DUO_UNKNOWN") == 0);
  EXPECT(duo_model_get_info(NULL, NULL), DUO_NULL_PARAMETER);
  n = duo_last_error_message(NULL, 0);
  CHECK(n > 0);
  memset(buf, 'x', sizeof buf);
  CHECK(duo_last_error_message(buf, sizeof buf) == n);
  CHECK(buf[7] == '\0' && strlen(buf) == 7); /* truncated */
  CHECK(sizeof(duo_leader_frame) == 660);
  CHECK(sizeof(duo_follower_frame) == 1560);
  CHECK(sizeof(duo_session_config) == 64);
  CHECK(sizeof(duo_model_info) == 32);
}

static void test_conversions(void) {
  duo_vec3 left = {1.0f, 0.0f, 0.0f}, u, r;
  duo_quat q = {0.1f, 0.2f, 0.3f, 0.927362f};
  duo_quat qu = duo_quat_to_unity(q), qr = duo_quat_to_unreal(q), back;
  duo_follower_frame f;
  u = duo_vec3_to_unity(left);
  r = duo_vec3_to_unreal(left);
  CHECK(u.x == -1.0f && u.y == 0.0f && u.z == 0.0f);
  CHECK(r.x == 0.0f && r.y == -100.0f && r.z == 0.0f);
  CHECK(qu.x == 0.1f && qu.y == -0.2f && qu.z == -0.3f && qu.w == q.w);
  back = duo_quat_from_unreal(qr);
  CHECK(back.x == q.x && back.y == q.y && back.z == q.z && back.w == q.w);
  u = duo_vec3_from_unity(duo_vec3_to_unity(left));
  CHECK(u.x == 1.0f);
  memset(&f, 0, sizeof f);
  f.root.x = 1.0f;
  EXPECT(duo_follower_frame_convert(&f, DUO_COORDS_UNITY), DUO_OK);
  CHECK(f.root.x == -1.0f);
  EXPECT(duo_follower_frame_convert(&f, 9), DUO_INVALID_ARGUMENT);
  EXPECT(duo_follower_frame_convert(NULL, DUO_COORDS_UNITY), DUO_NULL_PARAMETER);
  EXPECT(duo_leader_frame_convert(NULL, DUO_COORDS_UNITY), DUO_NULL_PARAMETER);
}

/* Asset padding and non-finite weights (docs/FORMAT.md rules 13, 15). */
static void test_model_padding_and_weights(const unsigned char *bytes, size_t len) {
  const size_t pad = 4096 + 7;
  unsigned char *p = NULL;
  duo_model *m = NULL, *sentinel = (duo_model *)&m;
  size_t last = len - 1, at;
  char msg[512];
  const unsigned char nan_le[4] = {0x00, 0x00, 0xc0, 0x7f};
  CHECK(posix_memalign((void **)&p, 64, len + pad) == 0);
  /* Zero bytes after the data: the same model. */
  memcpy(p, bytes, len);
  memset(p + len, 0, pad);
  EXPECT(duo_model_open_bytes(p, len + pad, &m), DUO_OK);
  duo_model_free(m);
  EXPECT(duo_model_open_copy(p, len + 1, &m), DUO_OK);
  duo_model_free(m);
  /* A non-zero byte after them: refused, by file offset. */
  m = sentinel;
  p[len + 100] = 1;
  EXPECT(duo_model_open_bytes(p, len + pad, &m), DUO_BAD_MODEL);
  duo_last_error_message(msg, sizeof msg);
  CHECK(strstr(msg, "non-zero byte at file offset") != NULL);
  CHECK(m == sentinel);
  /* A NaN in the last tensor's last non-zero f32 element (the data ends
   * with it, then zero padding; payloads are 64-byte aligned). */
  while (last > 0 && bytes[last] == 0) last--;
  at = last & ~(size_t)3;
  memcpy(p, bytes, len);
  memcpy(p + at, nan_le, 4);
  EXPECT(duo_model_open_bytes(p, len, &m), DUO_BAD_MODEL);
  duo_last_error_message(msg, sizeof msg);
  CHECK(strstr(msg, "weight element") != NULL && strstr(msg, "is NaN") != NULL && strchr(msg, '`') != NULL);
  EXPECT(duo_model_open_copy(p, len, &m), DUO_BAD_MODEL);
  /* +inf there too. */
  p[at + 2] = 0x80;
  EXPECT(duo_model_open_bytes(p, len, &m), DUO_BAD_MODEL);
  duo_last_error_message(msg, sizeof msg);
  CHECK(strstr(msg, "is +inf") != NULL);
  CHECK(m == sentinel);
  free(p);
}

/* The header's buffer rule: NULL with count 0 is answered as a non-NULL
 * empty buffer; NULL with a count is DUO_NULL_PARAMETER. */
static void test_buffer_rule(duo_model *m) {
  duo_session_config c;
  duo_session *s = NULL, *t = NULL, *sentinel = (duo_session *)&c;
  duo_step_batch *b = NULL, *bsentinel = (duo_step_batch *)&c;
  uint32_t tokens[5] = {9, 9, 9, 9, 9};
  unsigned char mem[64];
  float feat[54];
  size_t failed = 0, bytes = 0;
  duo_model *msentinel = (duo_model *)&c, *mm = msentinel;
  memset(feat, 0, sizeof feat);
  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  EXPECT(duo_model_open_bytes(NULL, 0, &mm), DUO_BAD_MODEL);
  EXPECT(duo_model_open_copy(NULL, 0, &mm), DUO_BAD_MODEL);
  EXPECT(duo_model_open_copy(mem, 0, &mm), DUO_BAD_MODEL);
  EXPECT(duo_model_open_copy(NULL, 64, &mm), DUO_NULL_PARAMETER);
  CHECK(mm == msentinel);
  EXPECT(duo_model_seed_tokens(m, NULL, NULL, 0, tokens), DUO_INVALID_ARGUMENT);
  EXPECT(duo_model_seed_tokens(m, feat, feat, 0, tokens), DUO_INVALID_ARGUMENT);
  EXPECT(duo_model_seed_tokens(m, (const float *)leader, NULL, 8, tokens), DUO_NULL_PARAMETER);
  CHECK(tokens[0] == 9);
  s = sentinel;
  EXPECT(duo_session_new_in(m, &c, seed, NULL, 0, &s), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_session_new_in(m, &c, seed, mem, 0, &s), DUO_BUFFER_TOO_SMALL);
  CHECK(s == sentinel);
  EXPECT(duo_step_batch_bytes(m, &c, 2, &bytes), DUO_OK);
  b = bsentinel;
  EXPECT(duo_step_batch_new_in(m, &c, 2, NULL, 0, &b), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_step_batch_new_in(m, &c, 2, mem, 0, &b), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_step_batch_new_in(m, &c, 2, NULL, bytes, &b), DUO_NULL_PARAMETER);
  CHECK(b == bsentinel);
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  EXPECT(duo_session_new(m, &c, seed, &t), DUO_OK);
  EXPECT(duo_session_push_music(s, NULL, 0), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_push_music(s, feat, 0), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_push_music(s, NULL, 54), DUO_NULL_PARAMETER);
  EXPECT(duo_session_set_music_track(s, NULL, 0), DUO_OK);
  EXPECT(duo_session_set_music_track(t, feat, 0), DUO_OK);
  EXPECT(duo_session_set_music_track(s, music, 54), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_set_music_track(t, music, 54), DUO_INVALID_ARGUMENT);
  EXPECT(duo_step_batch_new(m, &c, 2, &b), DUO_OK);
  EXPECT(duo_step_batch_push_leader(b, NULL, NULL, 0, &failed), DUO_OK);
  CHECK(failed == DUO_NO_SESSION);
  EXPECT(duo_step_batch_push_leader(b, NULL, leader, 2, &failed), DUO_NULL_PARAMETER);
  duo_step_batch_free(b);
  duo_session_free(s);
  duo_session_free(t);
}

/* duo_step_batch_push_leader's order: the sessions (NULL, twice, another
 * model) before the frames before the backlog, each by index. */
static void test_batch_order(duo_model *m) {
  duo_session_config c;
  duo_model *other = NULL;
  duo_session *ss[5];
  duo_step_batch *b = NULL;
  duo_leader_frame fr[5];
  size_t i, failed = 0;
  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  EXPECT(duo_model_open_file(model_path, &other), DUO_OK);
  for (i = 0; i < 5; i++) {
    EXPECT(duo_session_new(i == 4 ? other : m, &c, seed, &ss[i]), DUO_OK);
    EXPECT(duo_session_set_music_track(ss[i], music, n_frames * 54), DUO_OK);
    fr[i] = leader[0];
  }
  /* Session 1 backlogged. */
  for (i = 0; i < n_frames && duo_session_push_leader(ss[1], &leader[i]) == DUO_OK; i++) {
  }
  CHECK(i < n_frames);
  EXPECT(duo_step_batch_new(m, &c, 5, &b), DUO_OK);
  EXPECT(duo_step_batch_push_leader(b, ss, fr, 5, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == 4); /* another model at 4 before the backlog at 1 */
  fr[0].joints[3].x = (float)NAN;
  EXPECT(duo_step_batch_push_leader(b, ss, fr, 5, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == 4); /* before a bad frame 0 */
  fr[0] = leader[0];
  fr[3].joints[3].x = (float)INFINITY;
  EXPECT(duo_step_batch_push_leader(b, ss, fr, 4, &failed), DUO_NON_FINITE_INPUT);
  CHECK(failed == 3); /* a bad frame 3 before the backlog at 1 */
  fr[3] = leader[0];
  EXPECT(duo_step_batch_push_leader(b, ss, fr, 4, &failed), DUO_BACKLOG);
  CHECK(failed == 1);
  duo_step_batch_free(b);
  for (i = 0; i < 5; i++) duo_session_free(ss[i]);
  duo_model_free(other);
}

static void test_model_open(duo_model **out_file_model) {
  size_t len = 0;
  unsigned char *bytes = read_file(model_path, &len);
  void *aligned = NULL;
  unsigned char *odd;
  duo_model *m = NULL, *sentinel = (duo_model *)&len;
  duo_model_info info;
  CHECK(bytes != NULL);
  /* From a file (mmap). */
  EXPECT(duo_model_open_file(model_path, &m), DUO_OK);
  EXPECT(duo_model_get_info(m, &info), DUO_OK);
  CHECK(info.joints == 55 && info.music_features == 54 && info.fps == 30);
  CHECK(info.frames_per_token == 4 && info.mapped == 1);
  CHECK(info.family == DUO_FAMILY_DUOLANDO);
  *out_file_model = m;
  /* From aligned memory, without a copy. */
  CHECK(posix_memalign(&aligned, 64, len) == 0);
  memcpy(aligned, bytes, len);
  m = NULL;
  EXPECT(duo_model_open_bytes((const uint8_t *)aligned, len, &m), DUO_OK);
  EXPECT(duo_model_get_info(m, &info), DUO_OK);
  CHECK(info.mapped == 0);
  duo_model_free(m);
  /* Misaligned memory: refused without a copy, accepted with one. */
  odd = (unsigned char *)malloc(len + 1);
  memcpy(odd + 1, bytes, len);
  m = sentinel;
  EXPECT(duo_model_open_bytes(odd + 1, len, &m), DUO_INVALID_ARGUMENT);
  CHECK(m == sentinel); /* outputs only on success */
  EXPECT(duo_model_open_copy(odd + 1, len, &m), DUO_OK);
  free(odd); /* the copy owns its bytes */
  EXPECT(duo_model_get_info(m, &info), DUO_OK);
  duo_model_free(m);
  /* Truncated, empty, garbage. */
  m = sentinel;
  EXPECT(duo_model_open_bytes((const uint8_t *)aligned, len / 2, &m), DUO_BAD_MODEL);
  EXPECT(duo_model_open_bytes((const uint8_t *)aligned, 23, &m), DUO_BAD_MODEL);
  EXPECT(duo_model_open_copy(bytes, len - 1, &m), DUO_BAD_MODEL);
  EXPECT(duo_model_open_bytes(NULL, 0, &m), DUO_BAD_MODEL);
  memset(aligned, 0xAB, 64);
  EXPECT(duo_model_open_bytes((const uint8_t *)aligned, len, &m), DUO_BAD_MODEL);
  /* NULLs and missing files. */
  EXPECT(duo_model_open_bytes(NULL, 10, &m), DUO_NULL_PARAMETER);
  EXPECT(duo_model_open_bytes(bytes, len, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_model_open_copy(bytes, len, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_model_open_file(NULL, &m), DUO_NULL_PARAMETER);
  EXPECT(duo_model_open_file(model_path, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_model_open_file("/nonexistent/dir/model.duo", &m), DUO_IO);
  {
    char msg[256];
    duo_last_error_message(msg, sizeof msg);
    CHECK(strstr(msg, "/nonexistent/dir/model.duo") != NULL);
  }
  CHECK(m == sentinel);
  duo_model_free(NULL);
  free(aligned);
  test_model_padding_and_weights(bytes, len);
  free(bytes);
}

static void test_session_errors(duo_model *m) {
  duo_session_config c, bad;
  duo_session *s = NULL, *sentinel = (duo_session *)&c;
  duo_follower_frame f;
  size_t bytes = 0;
  unsigned char *mem;
  float feat[55]; /* 55 readable: the wrong-length call below passes 55 */
  const uint32_t big_seed[5] = {100000, 0, 0, 0, 0};
  uint32_t tokens[5], lat = 77;

  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  EXPECT(duo_session_config_minimum(NULL, &c), DUO_NULL_PARAMETER);
  EXPECT(duo_session_config_reference(m, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_session_bytes(m, &c, &bytes), DUO_OK);
  CHECK(bytes > 0);
  bad = c;
  bad.shift = 0;
  s = sentinel;
  EXPECT(duo_session_new(m, &bad, seed, &s), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_bytes(m, &bad, &bytes), DUO_INVALID_ARGUMENT);
  bad = c;
  bad.sampling = 5;
  EXPECT(duo_session_new(m, &bad, seed, &s), DUO_INVALID_ARGUMENT);
  bad = c;
  bad.kv = 2;
  EXPECT(duo_session_new(m, &bad, seed, &s), DUO_INVALID_ARGUMENT);
  bad = c;
  bad.lookahead = 1000;
  EXPECT(duo_session_new(m, &bad, seed, &s), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_new(m, &c, big_seed, &s), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_new(NULL, &c, seed, &s), DUO_NULL_PARAMETER);
  EXPECT(duo_session_new(m, NULL, seed, &s), DUO_NULL_PARAMETER);
  EXPECT(duo_session_new(m, &c, NULL, &s), DUO_NULL_PARAMETER);
  EXPECT(duo_session_new(m, &c, seed, NULL), DUO_NULL_PARAMETER);
  mem = (unsigned char *)malloc(bytes);
  EXPECT(duo_session_new_in(m, &c, seed, mem, bytes - 1, &s), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_session_new_in(m, &c, seed, NULL, bytes, &s), DUO_NULL_PARAMETER);
  CHECK(s == sentinel);
  free(mem);

  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  EXPECT(duo_session_latency_frames(s, &lat), DUO_OK);
  /* No track: music pushed music_lookahead tokens ahead, 4 (d + 1) - 1. */
  CHECK(lat == 3);
  EXPECT(duo_session_latency_frames(NULL, &lat), DUO_NULL_PARAMETER);
  EXPECT(duo_session_latency_frames(s, NULL), DUO_NULL_PARAMETER);
  f.index = 4242;
  EXPECT(duo_session_pull_follower(s, &f), DUO_NOT_READY);
  CHECK(f.index == 4242);
  EXPECT(duo_session_pull_follower(s, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_session_pull_follower(NULL, &f), DUO_NULL_PARAMETER);
  EXPECT(duo_session_push_leader(s, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_session_push_leader(NULL, &leader[0]), DUO_NULL_PARAMETER);
  memset(feat, 0, sizeof feat);
  EXPECT(duo_session_push_music(s, feat, 53), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_push_music(s, feat, 55), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_push_music(s, NULL, 54), DUO_NULL_PARAMETER);
  feat[3] = (float)NAN;
  EXPECT(duo_session_push_music(s, feat, 54), DUO_NON_FINITE_INPUT);
  feat[3] = 0.0f;
  EXPECT(duo_session_push_music(s, feat, 54), DUO_OK);
  EXPECT(duo_session_set_music_track(s, music, 53), DUO_INVALID_ARGUMENT);
  /* Music was pushed: a track, empty or not, NULL or not, is refused alike. */
  EXPECT(duo_session_set_music_track(s, NULL, 0), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_set_music_track(s, music, 0), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_set_music_track(s, NULL, 54), DUO_NULL_PARAMETER);
  EXPECT(duo_session_reset(s, big_seed), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_reset(s, NULL), DUO_NULL_PARAMETER);
  EXPECT(duo_session_reset(NULL, seed), DUO_NULL_PARAMETER);
  EXPECT(duo_session_reset(s, seed), DUO_OK);

  /* Backlog: push without pulling until refused, then drain. */
  {
    size_t i, pushed = 0, pulled = 0;
    duo_result r = DUO_OK;
    EXPECT(duo_session_set_music_track(s, music, n_frames * 54), DUO_OK);
    EXPECT(duo_session_latency_frames(s, &lat), DUO_OK);
    CHECK(lat == 0); /* with the track */
    for (i = 0; i < n_frames && r == DUO_OK; i++) {
      r = duo_session_push_leader(s, &leader[i]);
      if (r == DUO_OK) pushed++;
    }
    CHECK(r == DUO_BACKLOG);
    CHECK(pushed == c.pending_frames + lat + 1);
    while (duo_session_pull_follower(s, &f) == DUO_OK) pulled++;
    CHECK(pulled == pushed);
    EXPECT(duo_session_push_leader(s, &leader[pushed]), DUO_OK);
  }

  /* Seed tokens from start frames (8 frames of the leader as both). */
  EXPECT(duo_model_seed_tokens(m, (const float *)leader, (const float *)leader, 8, tokens), DUO_OK);
  EXPECT(duo_session_reset(s, tokens), DUO_OK);
  EXPECT(duo_model_seed_tokens(m, (const float *)leader, (const float *)leader, 2, tokens), DUO_INVALID_ARGUMENT);
  EXPECT(duo_model_seed_tokens(m, NULL, (const float *)leader, 8, tokens), DUO_NULL_PARAMETER);
  EXPECT(duo_model_seed_tokens(m, (const float *)leader, (const float *)leader, 8, NULL), DUO_NULL_PARAMETER);
  duo_session_free(s);
  duo_session_free(NULL);
}

/* The drain (duo_session_finish), DUO_ENDED, the music buffer and the
 * presets (issues #36 §3, #37 §1). */
static void test_finish(duo_model *m) {
  duo_session_config c, p;
  duo_session *s = NULL;
  duo_follower_frame f;
  uint32_t seed[5] = {0, 0, 0, 0, 0};
  size_t i, got = 0;
  float feat[54];
  duo_result r;
  EXPECT(duo_session_config_preset(m, "reference", &c), DUO_OK);
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  EXPECT(duo_session_set_music_track(s, music, n_frames * 54), DUO_OK);
  for (i = 0; i < n_frames; i++) {
    r = duo_session_push_leader(s, &leader[i]);
    CHECK(r == DUO_OK);
    while (duo_session_pull_follower(s, &f) == DUO_OK) got++;
  }
  /* Without the end the reference budget's last frames never come. */
  CHECK(got < 4 * ((n_frames - 4) / 4 - 29 + 1));
  EXPECT(duo_session_finish(s), DUO_OK);
  EXPECT(duo_session_finish(s), DUO_OK);
  EXPECT(duo_session_push_leader(s, &leader[0]), DUO_ENDED);
  while ((r = duo_session_pull_follower(s, &f)) == DUO_OK) {
    CHECK(f.index == got);
    CHECK(frame_finite(&f));
    got++;
  }
  CHECK(r == DUO_NOT_READY);
  /* The offline model's count: 4 (K + 1), K = (T4 - 4) / 4 - 29 (32 here). */
  CHECK(got == 4 * ((n_frames - 4) / 4 - 29 + 1));
  CHECK(strcmp(duo_result_name(DUO_ENDED), "DUO_ENDED") == 0);
  EXPECT(duo_session_finish(NULL), DUO_NULL_PARAMETER);
  /* The music buffer holds music_buffer_frames frames, no more. */
  EXPECT(duo_session_reset(s, seed), DUO_OK);
  memset(feat, 0, sizeof feat);
  CHECK(c.music_buffer_frames == 440);
  for (i = 0; i < 1000; i++)
    if ((r = duo_session_push_music(s, feat, 54)) != DUO_OK) break;
  CHECK(i == 440);
  CHECK(r == DUO_BACKLOG);
  EXPECT(duo_session_push_leader(s, &leader[0]), DUO_OK); /* taken again after the reset */
  duo_session_free(s);
  /* Presets: the list the CLI takes. */
  EXPECT(duo_session_config_preset(m, "live-music", &p), DUO_OK);
  CHECK(p.music_lookahead == 0 && p.lookahead == 4 && p.enc_future == 2 && p.dec_future == 2);
  EXPECT(duo_session_config_preset(m, "interactive", &p), DUO_OK);
  CHECK(p.music_lookahead == 29 && p.lookahead == 4);
  EXPECT(duo_session_config_preset(m, "minimum", &p), DUO_OK);
  CHECK(p.lookahead == 0 && p.enc_future == 0 && p.dec_future == 0);
  EXPECT(duo_session_config_preset(m, "fastest", &p), DUO_INVALID_ARGUMENT);
  EXPECT(duo_session_config_preset(m, NULL, &p), DUO_NULL_PARAMETER);
  EXPECT(duo_session_config_preset(NULL, "minimum", &p), DUO_NULL_PARAMETER);
  EXPECT(duo_session_config_preset(m, "minimum", NULL), DUO_NULL_PARAMETER);
}

/* Reference output of one clean run, for comparisons. */
static duo_follower_frame *reference = NULL;
static size_t reference_n = 0;

static int same_frames(const duo_follower_frame *a, const duo_follower_frame *b, size_t n) {
  return memcmp(a, b, n * sizeof *a) == 0;
}

static void test_sessions(duo_model *m) {
  duo_session_config c;
  duo_session *s = NULL, *t = NULL;
  size_t bytes = 0, n;
  unsigned char *mem;
  char msg[512];
  duo_follower_frame *out = (duo_follower_frame *)malloc(n_frames * sizeof *out);

  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  reference = (duo_follower_frame *)malloc(n_frames * sizeof *reference);
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  reference_n = drive(s, reference, n_frames, 0);
  CHECK(reference_n > n_frames / 2);
  /* Reset reproduces the run exactly; rejected frames change nothing. */
  EXPECT(duo_session_reset(s, seed), DUO_OK);
  n = drive(s, out, n_frames, 1);
  CHECK(n == reference_n && same_frames(out, reference, n));
  duo_session_free(s);

  /* Caller memory, at an odd address. */
  EXPECT(duo_session_bytes(m, &c, &bytes), DUO_OK);
  mem = (unsigned char *)malloc(bytes + 3);
  EXPECT(duo_session_new_in(m, &c, seed, mem + 3, bytes, &t), DUO_OK);
  n = drive(t, out, n_frames, 0);
  CHECK(n == reference_n && same_frames(out, reference, n));
  duo_session_free(t);
  free(mem);

  /* A top-k session: finite, and reproducible for one rng_seed. */
  c.sampling = DUO_SAMPLING_TOP_K;
  c.top_k = 3;
  c.rng_seed = 7;
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  n = drive(s, out, n_frames, 0);
  CHECK(n == reference_n);
  {
    duo_follower_frame *again = (duo_follower_frame *)malloc(n_frames * sizeof *again);
    EXPECT(duo_session_reset(s, seed), DUO_OK);
    CHECK(drive(s, again, n_frames, 0) == n && same_frames(out, again, n));
    free(again);
  }
  duo_session_free(s);

  /* A softmax session: finite and reproducible too; its temperature and
   * the reserved field are checked by name. */
  c.sampling = DUO_SAMPLING_SOFTMAX;
  c.top_k = 8;
  c.temperature_milli = 0;
  s = NULL;
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_INVALID_ARGUMENT);
  duo_last_error_message(msg, sizeof msg);
  CHECK(s == NULL && strstr(msg, "temperature_milli") != NULL);
  c.temperature_milli = 1000;
  c.reserved = 1;
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_INVALID_ARGUMENT);
  duo_last_error_message(msg, sizeof msg);
  CHECK(s == NULL && strstr(msg, "reserved") != NULL);
  c.reserved = 0;
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  n = drive(s, out, n_frames, 0);
  CHECK(n == reference_n);
  {
    duo_follower_frame *again = (duo_follower_frame *)malloc(n_frames * sizeof *again);
    EXPECT(duo_session_reset(s, seed), DUO_OK);
    CHECK(drive(s, again, n_frames, 0) == n && same_frames(out, again, n));
    free(again);
  }
  duo_session_free(s);
  free(out);
}

/* Two sessions stepped together through a duo_step_batch (the second on
 * the x-mirrored leader, in caller memory) equal the same sessions stepped
 * alone, byte for byte; refusals name the session and change nothing. */
static void test_step_batch(duo_model *m) {
  duo_session_config c;
  duo_session *ss[2] = {NULL, NULL}, *alone = NULL;
  duo_step_batch *b = NULL;
  duo_leader_frame *mirrored = (duo_leader_frame *)malloc(n_frames * sizeof *mirrored);
  duo_follower_frame *out[2], *want = (duo_follower_frame *)malloc(n_frames * sizeof *want);
  size_t got[2] = {0, 0}, want_n, i, k, bytes = 0, failed = 0;
  unsigned char *mem;
  duo_follower_frame f;
  int done = 0;

  out[0] = (duo_follower_frame *)malloc(n_frames * sizeof *out[0]);
  out[1] = (duo_follower_frame *)malloc(n_frames * sizeof *out[1]);
  for (i = 0; i < n_frames; i++) {
    mirrored[i] = leader[i];
    for (k = 0; k < DUO_JOINTS; k++) mirrored[i].joints[k].x = -mirrored[i].joints[k].x;
  }
  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  /* The mirrored dancer alone. */
  {
    duo_leader_frame *saved = leader;
    EXPECT(duo_session_new(m, &c, seed, &alone), DUO_OK);
    leader = mirrored;
    want_n = drive(alone, want, n_frames, 0);
    leader = saved;
    duo_session_free(alone);
  }
  CHECK(want_n == reference_n && !same_frames(want, reference, want_n));

  EXPECT(duo_step_batch_new(m, &c, 0, &b), DUO_INVALID_ARGUMENT);
  EXPECT(duo_step_batch_bytes(m, &c, 2, &bytes), DUO_OK);
  mem = (unsigned char *)malloc(bytes + 5);
  EXPECT(duo_step_batch_new_in(m, &c, 2, mem + 5, bytes - 1, &b), DUO_BUFFER_TOO_SMALL);
  CHECK(b == NULL);
  EXPECT(duo_step_batch_new_in(m, &c, 2, mem + 5, bytes, &b), DUO_OK);
  EXPECT(duo_session_new(m, &c, seed, &ss[0]), DUO_OK);
  EXPECT(duo_session_new(m, &c, seed, &ss[1]), DUO_OK);
  for (k = 0; k < 2; k++) EXPECT(duo_session_set_music_track(ss[k], music, n_frames * 54), DUO_OK);
  for (i = 0; i < n_frames && !done; i++) {
    duo_leader_frame two[2];
    duo_session *same[2];
    duo_result r;
    two[0] = leader[i];
    two[1] = mirrored[i];
    if (i % 6 == 1) {
      same[0] = ss[1];
      same[1] = ss[1];
      EXPECT(duo_step_batch_push_leader(b, same, two, 2, &failed), DUO_INVALID_ARGUMENT);
      CHECK(failed == 1);
      two[1].joints[7].y = (float)NAN;
      EXPECT(duo_step_batch_push_leader(b, ss, two, 2, &failed), DUO_NON_FINITE_INPUT);
      CHECK(failed == 1);
      EXPECT(duo_step_batch_push_leader(b, ss, two, 3, &failed), DUO_INVALID_ARGUMENT);
      CHECK(failed == DUO_NO_SESSION);
      two[1] = mirrored[i];
    }
    r = duo_step_batch_push_leader(b, ss, two, 2, &failed);
    if (r == DUO_BACKLOG) break; /* the music track's end, as in drive() */
    CHECK(r == DUO_OK && failed == DUO_NO_SESSION);
    for (k = 0; k < 2; k++) {
      while ((r = duo_session_pull_follower(ss[k], &f)) == DUO_OK) {
        if (got[k] < n_frames) out[k][got[k]] = f;
        got[k]++;
      }
      CHECK(r == DUO_NOT_READY);
      if (got[k] > n_frames) done = 1;
    }
  }
  CHECK(got[0] == reference_n && same_frames(out[0], reference, reference_n));
  CHECK(got[1] == want_n && same_frames(out[1], want, want_n));
  duo_step_batch_free(b);
  duo_step_batch_free(NULL);
  free(mem);
  duo_session_free(ss[0]);
  duo_session_free(ss[1]);
  free(out[0]);
  free(out[1]);
  free(want);
  free(mirrored);
}

struct worker {
  duo_model *model;
  int ok;
};

static void *worker_main(void *arg) {
  struct worker *w = (struct worker *)arg;
  duo_session_config c;
  duo_session *s = NULL;
  duo_follower_frame *out = (duo_follower_frame *)malloc(n_frames * sizeof *out);
  size_t n;
  int round;
  w->ok = duo_session_config_minimum(w->model, &c) == DUO_OK &&
          duo_session_new(w->model, &c, seed, &s) == DUO_OK;
  for (round = 0; round < 2 && w->ok; round++) {
    n = drive(s, out, n_frames, round);
    w->ok = n == reference_n && same_frames(out, reference, n) && duo_session_reset(s, seed) == DUO_OK;
  }
  /* Errors are per thread. */
  if (w->ok) {
    char msg[64];
    w->ok = duo_session_push_leader(s, NULL) == DUO_NULL_PARAMETER &&
            duo_last_error_message(msg, sizeof msg) > 0;
  }
  duo_session_free(s);
  free(out);
  return NULL;
}

static void test_threads(duo_model *m) {
  pthread_t th[4];
  struct worker w[4];
  int i;
  for (i = 0; i < 4; i++) {
    w[i].model = m;
    w[i].ok = 0;
    CHECK(pthread_create(&th[i], NULL, worker_main, &w[i]) == 0);
  }
  for (i = 0; i < 4; i++) {
    CHECK(pthread_join(th[i], NULL) == 0);
    CHECK(w[i].ok);
  }
}

static void test_model_freed_first(void) {
  duo_model *m = NULL;
  duo_session *s = NULL;
  duo_session_config c;
  duo_follower_frame f;
  size_t i, got = 0;
  EXPECT(duo_model_open_file(model_path, &m), DUO_OK);
  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  EXPECT(duo_session_new(m, &c, seed, &s), DUO_OK);
  duo_model_free(m); /* the session keeps the weights alive */
  EXPECT(duo_session_set_music_track(s, music, n_frames * 54), DUO_OK);
  for (i = 0; i < 40; i++) {
    EXPECT(duo_session_push_leader(s, &leader[i]), DUO_OK);
    while (duo_session_pull_follower(s, &f) == DUO_OK) {
      CHECK(got < reference_n && memcmp(&f, &reference[got], sizeof f) == 0);
      got++;
    }
  }
  CHECK(got > 0);
  duo_session_free(s);
}

/* ---- a solo (Bailando) model ------------------------------------------ */

/* The Bailando fixture: info, a session fed the golden music row by row
 * and finished gives the authors' positions (within 1e-5 m); the
 * Duolando-only calls are refused by name; freeing the model before the
 * session is fine. */
static void test_solo(void) {
  char path[1200];
  size_t n_music = 0, n_pos = 0, got = 0, i;
  float *rows, *want, f[DUO_BAILANDO_JOINTS * 3];
  duo_model *m = NULL;
  duo_model_info info;
  duo_session_config c;
  duo_session *s = NULL;
  duo_follower_frame ff;
  uint64_t index = 0;
  float worst = 0.0f;
  char msg[512];
  const uint32_t solo_seed[2] = {15, 14}; /* the golden's seed tokens (meta.json) */
  sprintf(path, "%s/tests/fixtures/bailando_rollout_btiny_demo_odd/music.npy", root_dir);
  rows = read_npy_f32(path, &n_music);
  sprintf(path, "%s/tests/fixtures/bailando_rollout_btiny_demo_odd/pos3d.npy", root_dir);
  want = read_npy_f32(path, &n_pos);
  CHECK(rows != NULL && want != NULL);
  if (!rows || !want) return;
  sprintf(path, "%s/tests/fixtures/bailando_btiny/model.duo", root_dir);
  EXPECT(duo_model_open_file(path, &m), DUO_OK);
  EXPECT(duo_model_get_info(m, &info), DUO_OK);
  CHECK(info.family == DUO_FAMILY_BAILANDO && info.joints == DUO_BAILANDO_JOINTS && info.music_features == 438 && info.fps == 60);
  EXPECT(duo_session_config_preset(m, "exact", &c), DUO_OK);
  EXPECT(duo_session_new(m, &c, solo_seed, &s), DUO_OK);
  duo_model_free(m); /* the session keeps the weights alive */
  EXPECT(duo_session_push_leader(s, &leader[0]), DUO_INVALID_ARGUMENT);
  duo_last_error_message(msg, sizeof msg);
  CHECK(strstr(msg, "Bailando") != NULL);
  EXPECT(duo_session_pull_follower(s, &ff), DUO_INVALID_ARGUMENT);
  for (i = 0; i + 438 <= n_music; i += 438) {
    EXPECT(duo_session_push_music(s, rows + i, 438), DUO_OK);
    while (duo_session_pull_positions(s, f, DUO_BAILANDO_JOINTS * 3, &index) == DUO_OK) {
      size_t j;
      CHECK(index == got);
      for (j = 0; j < DUO_BAILANDO_JOINTS * 3 && (got + 1) * 72 <= n_pos; j++) {
        float d = fabsf(f[j] - want[got * 72 + j]);
        if (!(d <= worst)) worst = d;
      }
      got++;
    }
  }
  EXPECT(duo_session_finish(s), DUO_OK);
  while (duo_session_pull_positions(s, f, DUO_BAILANDO_JOINTS * 3, &index) == DUO_OK) {
    size_t j;
    for (j = 0; j < DUO_BAILANDO_JOINTS * 3 && (got + 1) * 72 <= n_pos; j++) {
      float d = fabsf(f[j] - want[got * 72 + j]);
      if (!(d <= worst)) worst = d;
    }
    got++;
  }
  CHECK(got * 72 == n_pos);
  if (!(worst <= 1e-5f)) fprintf(stderr, "solo: max abs err %g over %zu frames\n", (double)worst, got);
  CHECK(worst <= 1e-5f);
  duo_session_free(s);
  free(rows);
  free(want);
}

/* ---- a Transflower model ---------------------------------------------- */

/* The Transflower paper fixture: info; an "exact" session fed the audio
 * row by row, replaying the recorded base samples, gives the authors'
 * frames (output.npy) within the paper case's tolerance (4 x the
 * reference's own float32-vs-float64 difference: 9.7e-6 relative,
 * docs/TRANSFLOWER.md); a seeded session repeats itself after reset; the
 * other families' calls are refused by name; the model may be freed first. */
static void test_transflower(void) {
  char path[1200];
  size_t n_motion = 0, n_audio = 0, n_noise = 0, n_want = 0, got = 0, i, j;
  float *motion, *audio, *noise, *want, f[64], first[64];
  duo_model *m = NULL;
  duo_model_info mi;
  duo_transflower_info info;
  duo_transflower_config c;
  duo_session *s = NULL, *placed = NULL;
  uint64_t index = 0;
  float worst = 0.0f, scale = 1.0f;
  char msg[512];
  size_t bytes = 0;
  unsigned char *mem = NULL;
  sprintf(path, "%s/tests/fixtures/transflower_paper/in_expmap_scaled_20.npy", root_dir);
  motion = read_npy_f32(path, &n_motion);
  sprintf(path, "%s/tests/fixtures/transflower_paper/in_audio_feats_scaled_20.npy", root_dir);
  audio = read_npy_f32(path, &n_audio);
  sprintf(path, "%s/tests/fixtures/transflower_paper/noise.npy", root_dir);
  noise = read_npy_f32(path, &n_noise);
  sprintf(path, "%s/tests/fixtures/transflower_paper/output.npy", root_dir);
  want = read_npy_f32(path, &n_want);
  CHECK(motion && audio && noise && want);
  if (!motion || !audio || !noise || !want) return;
  sprintf(path, "%s/tests/fixtures/transflower_paper/model.duo", root_dir);
  EXPECT(duo_model_open_file(path, &m), DUO_OK);
  EXPECT(duo_model_get_info(m, &mi), DUO_OK);
  CHECK(mi.family == DUO_FAMILY_TRANSFLOWER && mi.joints == 0 && mi.fps == 20);
  EXPECT(duo_transflower_get_info(m, &info), DUO_OK);
  CHECK(info.channels <= 64 && info.audio_features == mi.music_features && info.labels == 0);
  EXPECT(duo_transflower_config_preset(m, "exact", &c), DUO_OK);
  CHECK(c.refresh == 1);
  EXPECT(duo_transflower_session_new(m, &c, motion, (size_t)info.seed_rows * info.channels, NULL, 0, &s), DUO_OK);
  /* A seeded session in caller memory (at an odd address); a byte short is refused. */
  EXPECT(duo_transflower_session_bytes(m, &c, &bytes), DUO_OK);
  mem = (unsigned char *)malloc(bytes + 1);
  CHECK(mem != NULL);
  if (!mem) return;
  c.rng_seed = 11;
  EXPECT(duo_transflower_session_new_in(m, &c, motion, (size_t)info.seed_rows * info.channels, NULL, 0, mem + 1,
                                        bytes - 1, &placed),
         DUO_BUFFER_TOO_SMALL);
  CHECK(placed == NULL);
  EXPECT(duo_transflower_session_new_in(m, &c, motion, (size_t)info.seed_rows * info.channels, NULL, 0, mem + 1, bytes,
                                        &placed),
         DUO_OK);
  c.rng_seed = 0;
  duo_model_free(m); /* the sessions keep the weights alive */
  EXPECT(duo_session_push_leader(s, &leader[0]), DUO_INVALID_ARGUMENT);
  duo_last_error_message(msg, sizeof msg);
  CHECK(strstr(msg, "Transflower") != NULL);
  EXPECT(duo_session_pull_positions(s, f, 72, &index), DUO_INVALID_ARGUMENT);
  for (i = 0; i + info.audio_features <= n_audio; i += info.audio_features) {
    EXPECT(duo_session_push_music(s, audio + i, info.audio_features), DUO_OK);
    while ((got + 1) * info.noise_floats <= n_noise &&
           duo_transflower_pull_frame_with_noise(s, noise + got * info.noise_floats, info.noise_floats, f, info.channels, &index) == DUO_OK) {
      CHECK(index == got);
      for (j = 0; j < info.channels && (got + 1) * info.channels <= n_want; j++) {
        float d = fabsf(f[j] - want[got * info.channels + j]);
        if (!(d <= worst)) worst = d;
        if (fabsf(want[got * info.channels + j]) > scale) scale = fabsf(want[got * info.channels + j]);
      }
      got++;
    }
  }
  CHECK(got * info.channels == n_want);
  if (!(worst / scale <= 9.7e-6f)) fprintf(stderr, "transflower: rel err %g over %zu frames\n", (double)(worst / scale), got);
  CHECK(worst / scale <= 9.7e-6f);
  /* Seeded: the same seed, the same first frame. */
  for (j = 0; j < 2; j++) {
    EXPECT(duo_transflower_session_reset(s, 11), DUO_OK);
    EXPECT(duo_transflower_pull_frame(s, f, info.channels, &index), DUO_NOT_READY);
    EXPECT(duo_session_push_music(s, audio, (size_t)info.audio_window * info.audio_features), DUO_OK);
    EXPECT(duo_transflower_pull_frame(s, f, info.channels, &index), DUO_OK);
    CHECK(index == 0);
    if (j == 0) memcpy(first, f, sizeof f);
  }
  CHECK(memcmp(first, f, info.channels * sizeof(float)) == 0);
  EXPECT(duo_transflower_pull_frame(s, f, info.channels + 1, &index), DUO_INVALID_ARGUMENT);
  /* The caller-memory session made with rng_seed 11: the same first frame. */
  EXPECT(duo_session_push_music(placed, audio, (size_t)info.audio_window * info.audio_features), DUO_OK);
  EXPECT(duo_transflower_pull_frame(placed, f, info.channels, &index), DUO_OK);
  CHECK(index == 0 && memcmp(first, f, info.channels * sizeof(float)) == 0);
  duo_session_free(placed);
  free(mem);
  duo_session_free(s);
  free(motion);
  free(audio);
  free(noise);
  free(want);
}

/* Transflower sessions through a duo_step_batch: two sessions for batches
 * only (seeds 11 and 12, in caller memory) stepped through a batch in
 * caller memory (at an odd address) give the frames each gives alone,
 * byte for byte; the refusals of duo_step_batch_step in the header's order
 * name their session; the model may be freed before its batch. `duo` is a
 * Duolando model (its sessions and batches are refused). */
static size_t tf_alone(duo_model *m, duo_transflower_config c, const float *motion, const float *audio,
                       size_t rows, const duo_transflower_info *info, float *out, size_t cap) {
  duo_session *s = NULL;
  size_t got = 0, r;
  uint64_t index = 0;
  c.batched = 0;
  EXPECT(duo_transflower_session_new(m, &c, motion, (size_t)info->seed_rows * info->channels, NULL, 0, &s), DUO_OK);
  for (r = 0; r < rows; r++) {
    EXPECT(duo_session_push_music(s, audio + r * info->audio_features, info->audio_features), DUO_OK);
    while (got < cap && duo_transflower_pull_frame(s, out + got * info->channels, info->channels, &index) == DUO_OK) {
      CHECK(index == got);
      got++;
    }
  }
  duo_session_free(s);
  return got;
}

static void test_transflower_batch(duo_model *duo) {
  char path[1200];
  size_t n_motion = 0, n_audio = 0, rows, bytes = 0, sbytes = 0, full = 0, i, k;
  size_t want_n[2] = {0, 0}, got[2] = {0, 0}, stepped = 0, failed = 0;
  float *motion, *audio, want[2][64 * 32], out[2][64 * 32], f[64];
  duo_model *m = NULL, *other = NULL;
  duo_transflower_info info;
  duo_transflower_config c;
  duo_session *ss[2] = {NULL, NULL}, *stranger = NULL, *ds = NULL, *list[5], *many[DUO_MAX_BATCH + 1];
  duo_step_batch *b = NULL, *db = NULL;
  duo_session_config dc;
  unsigned char *mem, *smem;
  uint64_t index = 0;
  sprintf(path, "%s/tests/fixtures/transflower_paper/in_expmap_scaled_20.npy", root_dir);
  motion = read_npy_f32(path, &n_motion);
  sprintf(path, "%s/tests/fixtures/transflower_paper/in_audio_feats_scaled_20.npy", root_dir);
  audio = read_npy_f32(path, &n_audio);
  CHECK(motion && audio);
  if (!motion || !audio) return;
  sprintf(path, "%s/tests/fixtures/transflower_paper/model.duo", root_dir);
  EXPECT(duo_model_open_file(path, &m), DUO_OK);
  EXPECT(duo_model_open_file(path, &other), DUO_OK);
  EXPECT(duo_transflower_get_info(m, &info), DUO_OK);
  CHECK(info.channels <= 64);
  rows = n_audio / info.audio_features;
  EXPECT(duo_transflower_config_preset(m, "exact", &c), DUO_OK);
  c.pending_frames = 2;
  for (k = 0; k < 2; k++) {
    c.rng_seed = 11 + k;
    want_n[k] = tf_alone(m, c, motion, audio, rows, &info, want[k], 32);
  }
  CHECK(want_n[0] > 2 && want_n[0] == want_n[1] && memcmp(want[0], want[1], info.channels * sizeof(float)) != 0);

  /* Sizes: a batched session holds less; the batch in caller memory. */
  EXPECT(duo_transflower_session_bytes(m, &c, &full), DUO_OK);
  c.batched = 1;
  EXPECT(duo_transflower_session_bytes(m, &c, &sbytes), DUO_OK);
  CHECK(sbytes < full);
  EXPECT(duo_transflower_step_batch_bytes(m, &bytes), DUO_OK);
  mem = (unsigned char *)malloc(bytes + 3);
  smem = (unsigned char *)malloc(2 * sbytes);
  CHECK(mem && smem);
  if (!mem || !smem) return;
  EXPECT(duo_transflower_step_batch_new_in(m, mem + 3, bytes - 1, &b), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_transflower_step_batch_new_in(m, NULL, 0, &b), DUO_BUFFER_TOO_SMALL);
  EXPECT(duo_transflower_step_batch_new_in(m, NULL, bytes, &b), DUO_NULL_PARAMETER);
  EXPECT(duo_transflower_step_batch_new(duo, &b), DUO_INVALID_ARGUMENT);
  CHECK(b == NULL);
  EXPECT(duo_transflower_step_batch_new_in(m, mem + 3, bytes, &b), DUO_OK);
  for (k = 0; k < 2; k++) {
    c.rng_seed = 11 + k;
    EXPECT(duo_transflower_session_new_in(m, &c, motion, (size_t)info.seed_rows * info.channels, NULL, 0,
                                          smem + k * sbytes, sbytes, &ss[k]),
           DUO_OK);
  }
  EXPECT(duo_transflower_session_new(other, &c, motion, (size_t)info.seed_rows * info.channels, NULL, 0, &stranger),
         DUO_OK);
  EXPECT(duo_session_config_minimum(duo, &dc), DUO_OK);
  EXPECT(duo_session_new(duo, &dc, seed, &ds), DUO_OK);
  EXPECT(duo_step_batch_new(duo, &dc, 2, &db), DUO_OK);
  duo_model_free(m); /* the batch and the sessions keep the weights alive */
  duo_model_free(other);

  /* Refusals, in the header's order; nothing changes. */
  EXPECT(duo_step_batch_step(NULL, ss, 2, &stepped, &failed), DUO_NULL_PARAMETER);
  CHECK(failed == DUO_NO_SESSION);
  EXPECT(duo_step_batch_step(db, ss, 2, &stepped, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == DUO_NO_SESSION);
  EXPECT(duo_step_batch_push_leader(b, NULL, NULL, 0, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == DUO_NO_SESSION);
  stepped = 9;
  EXPECT(duo_step_batch_step(b, NULL, 0, &stepped, &failed), DUO_OK);
  CHECK(stepped == 0 && failed == DUO_NO_SESSION);
  for (i = 0; i <= DUO_MAX_BATCH; i++) many[i] = ss[0];
  EXPECT(duo_step_batch_step(b, many, DUO_MAX_BATCH + 1, &stepped, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == DUO_NO_SESSION);
  EXPECT(duo_step_batch_step(b, NULL, 2, &stepped, &failed), DUO_NULL_PARAMETER);
  CHECK(failed == DUO_NO_SESSION);
  list[0] = ss[0]; list[1] = ss[1]; list[2] = NULL; list[3] = ss[0]; list[4] = stranger;
  EXPECT(duo_step_batch_step(b, list, 5, &stepped, &failed), DUO_NULL_PARAMETER);
  CHECK(failed == 2);
  list[2] = ss[1];
  EXPECT(duo_step_batch_step(b, list, 5, &stepped, &failed), DUO_INVALID_ARGUMENT); /* twice */
  CHECK(failed == 2);
  list[2] = ds;
  EXPECT(duo_step_batch_step(b, list, 3, &stepped, &failed), DUO_INVALID_ARGUMENT); /* a Duolando session */
  CHECK(failed == 2);
  list[2] = stranger;
  EXPECT(duo_step_batch_step(b, list, 3, &stepped, &failed), DUO_INVALID_ARGUMENT); /* another model */
  CHECK(failed == 2);
  list[0] = ds; list[1] = ss[0];
  EXPECT(duo_step_batch_push_leader(db, list, leader, 2, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == 1);
  /* Backlog: session 1 with its 2 pending frames made; another model at 2 first. */
  EXPECT(duo_session_push_music(ss[1], audio, (size_t)(info.audio_window + 2) * info.audio_features), DUO_OK);
  for (k = 0; k < 2; k++) {
    EXPECT(duo_step_batch_step(b, &ss[1], 1, &stepped, &failed), DUO_OK);
    CHECK(stepped == 1 && failed == DUO_NO_SESSION);
  }
  list[0] = ss[0]; list[1] = ss[1]; list[2] = stranger;
  EXPECT(duo_step_batch_step(b, list, 3, &stepped, &failed), DUO_INVALID_ARGUMENT);
  CHECK(failed == 2);
  EXPECT(duo_step_batch_step(b, ss, 2, &stepped, &failed), DUO_BACKLOG);
  CHECK(failed == 1);
  /* A batched session's pull never steps. */
  EXPECT(duo_session_push_music(ss[0], audio, (size_t)info.audio_window * info.audio_features), DUO_OK);
  EXPECT(duo_transflower_pull_frame(ss[0], f, info.channels, &index), DUO_NOT_READY);

  /* Both through the batch, the rest of the audio row by row: each as alone. */
  for (k = 0; k < 2; k++)
    while (got[k] < 32 && duo_transflower_pull_frame(ss[k], out[k] + got[k] * info.channels, info.channels, &index) == DUO_OK) {
      CHECK(index == got[k]);
      got[k]++;
    }
  CHECK(got[0] == 0 && got[1] == 2);
  for (i = 0; i <= rows; i++) {
    if (i < rows) {
      if (i >= info.audio_window) EXPECT(duo_session_push_music(ss[0], audio + i * info.audio_features, info.audio_features), DUO_OK);
      if (i >= info.audio_window + 2) EXPECT(duo_session_push_music(ss[1], audio + i * info.audio_features, info.audio_features), DUO_OK);
    }
    do {
      EXPECT(duo_step_batch_step(b, ss, 2, &stepped, &failed), DUO_OK);
      for (k = 0; k < 2; k++)
        while (got[k] < 32 && duo_transflower_pull_frame(ss[k], out[k] + got[k] * info.channels, info.channels, &index) == DUO_OK) {
          CHECK(index == got[k]);
          got[k]++;
        }
    } while (stepped > 0);
  }
  for (k = 0; k < 2; k++) {
    CHECK(got[k] == want_n[k]);
    CHECK(memcmp(out[k], want[k], want_n[k] * info.channels * sizeof(float)) == 0);
  }
  duo_step_batch_free(b);
  duo_step_batch_free(db);
  free(mem);
  for (k = 0; k < 2; k++) duo_session_free(ss[k]);
  free(smem);
  duo_session_free(stranger);
  duo_session_free(ds);
  free(motion);
  free(audio);
}

/* Sessions bound to a batch (duo_session_new_batched): their state alone
 * in their memory (smaller than duo_session_bytes), the batch's step
 * memory borrowed for every call; frames equal to a session with its own
 * memory, byte for byte: one in caller memory driven alone, one bound to a
 * batch in caller memory whose handle is freed first, then three on
 * three threads at once sharing one batch whose handle was freed before
 * they start (the sessions keep it). */
struct bound_worker {
  duo_session *s;
  int ok;
};

static void *bound_main(void *arg) {
  struct bound_worker *w = (struct bound_worker *)arg;
  duo_follower_frame *out = (duo_follower_frame *)malloc(n_frames * sizeof *out);
  size_t n = drive(w->s, out, n_frames, 1);
  w->ok = n == reference_n && same_frames(out, reference, n);
  duo_session_free(w->s);
  free(out);
  return NULL;
}

static void test_batched_sessions(duo_model *m) {
  duo_session_config c;
  duo_step_batch *b = NULL;
  duo_session *s = NULL;
  size_t own = 0, bytes = 0, n;
  unsigned char *mem;
  duo_follower_frame *out = (duo_follower_frame *)malloc(n_frames * sizeof *out);
  pthread_t th[3];
  struct bound_worker w[3];
  int i;

  EXPECT(duo_session_config_minimum(m, &c), DUO_OK);
  EXPECT(duo_step_batch_new(m, &c, 1, &b), DUO_OK);
  EXPECT(duo_session_bytes(m, &c, &own), DUO_OK);
  EXPECT(duo_session_batched_bytes(m, &c, &bytes), DUO_OK);
  CHECK(bytes < own);
  mem = (unsigned char *)malloc(bytes + 7);
  EXPECT(duo_session_new_batched_in(m, &c, seed, b, mem + 7, bytes - 1, &s), DUO_BUFFER_TOO_SMALL);
  CHECK(s == NULL);
  EXPECT(duo_session_new_batched(m, &c, seed, NULL, &s), DUO_NULL_PARAMETER);
  EXPECT(duo_session_new_batched_in(m, &c, seed, b, mem + 7, bytes, &s), DUO_OK);
  n = drive(s, out, n_frames, 1);
  CHECK(n == reference_n && same_frames(out, reference, n));
  duo_session_free(s);
  free(mem);

  /* Session and batch both in caller memory; the batch's handle freed
   * first: the session drops it in place at its own free, then both
   * blocks go. */
  {
    size_t batch_bytes = 0;
    unsigned char *batch_mem;
    duo_step_batch *cb = NULL;
    EXPECT(duo_step_batch_bytes(m, &c, 1, &batch_bytes), DUO_OK);
    batch_mem = (unsigned char *)malloc(batch_bytes + 3);
    mem = (unsigned char *)malloc(bytes);
    EXPECT(duo_step_batch_new_in(m, &c, 1, batch_mem + 3, batch_bytes, &cb), DUO_OK);
    EXPECT(duo_session_new_batched_in(m, &c, seed, cb, mem, bytes, &s), DUO_OK);
    duo_step_batch_free(cb);
    n = drive(s, out, n_frames, 0);
    CHECK(n == reference_n && same_frames(out, reference, n));
    duo_session_free(s);
    free(mem);
    free(batch_mem);
  }

  for (i = 0; i < 3; i++) {
    w[i].s = NULL;
    w[i].ok = 0;
    EXPECT(duo_session_new_batched(m, &c, seed, b, &w[i].s), DUO_OK);
  }
  duo_step_batch_free(b);
  for (i = 0; i < 3; i++) CHECK(pthread_create(&th[i], NULL, bound_main, &w[i]) == 0);
  for (i = 0; i < 3; i++) {
    CHECK(pthread_join(th[i], NULL) == 0);
    CHECK(w[i].ok);
  }
  free(out);
}

int main(int argc, char **argv) {
  duo_model *m = NULL;
  if (argc < 2 || strlen(argv[1]) > 1000) {
    fprintf(stderr, "usage: %s <repo root>\n", argv[0]);
    return 2;
  }
  strcpy(root_dir, argv[1]);
  sprintf(model_path, "%s/tests/fixtures/tiny/model.duo", root_dir);
  if (!load_inputs()) {
    fprintf(stderr, "cannot read the fixture inputs under %s\n", root_dir);
    return 2;
  }
  test_errors_and_version();
  test_conversions();
  test_model_open(&m);
  test_session_errors(m);
  test_finish(m);
  test_buffer_rule(m);
  test_batch_order(m);
  test_sessions(m);
  test_step_batch(m);
  test_threads(m);
  test_batched_sessions(m);
  test_model_freed_first();
  test_solo();
  test_transflower();
  test_transflower_batch(m);
  duo_model_free(m);
  free(reference);
  free(leader);
  free(music);
  if (failures) {
    fprintf(stderr, "test_duolando: %d check(s) failed\n", failures);
    return 1;
  }
  printf("test_duolando: all checks passed (%zu leader frames, %zu follower frames per run)\n", n_frames, reference_n);
  return 0;
}
