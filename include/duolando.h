/* duolando.h — C ABI of the duolando engine (library `duolando`, crate duolando-ffi).
 *
 * Today: the version only. The model/session API (duo_model_*, duo_session_*)
 * comes with the streaming session.
 * Thread rules: every function here may be called from any thread. */
#ifndef DUOLANDO_H
#define DUOLANDO_H

#ifdef __cplusplus
extern "C" {
#endif

#define DUOLANDO_VERSION_MAJOR 0
#define DUOLANDO_VERSION_MINOR 1
#define DUOLANDO_VERSION_PATCH 0

/* The library version, e.g. "0.1.0": a static NUL-terminated string.
 * Never NULL; do not free it. */
const char *duo_version(void);

#ifdef __cplusplus
}
#endif

#endif /* DUOLANDO_H */
