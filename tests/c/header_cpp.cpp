// The header compiles as C++17 (extern "C", no C-only constructs) and can
// be included twice.
#include "duolando.h"
#include "duolando.h"

#include <type_traits>

static_assert(sizeof(duo_leader_frame) == 660, "duo_leader_frame layout");
static_assert(sizeof(duo_follower_frame) == 1560, "duo_follower_frame layout");
static_assert(sizeof(duo_session_config) == 64, "duo_session_config layout");
static_assert(std::is_trivially_copyable<duo_follower_frame>::value, "blittable");

int main() {
  duo_result (*open)(const char *, duo_model **) = duo_model_open_file;
  return open == nullptr;
}
