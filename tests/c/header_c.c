/* The header compiles as strict C99 and can be included twice. */
#include "duolando.h"
#include "duolando.h"

int main(void) {
  duo_follower_frame f;
  duo_session_config c;
  (void)f;
  (void)c;
  return (int)sizeof(duo_leader_frame) == 660 && sizeof(duo_transflower_info) == 48 &&
                 sizeof(duo_transflower_config) == 24
             ? 0
             : 1;
}
