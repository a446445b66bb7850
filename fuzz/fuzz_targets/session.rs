//! A streaming session on the tiny2 fixture fed an arbitrary config and up
//! to 256 operations (`duolando_gen::session::SessionInput`): leader and
//! music frames with NaN / Inf / huge / subnormal values and wrong lengths,
//! pulls, clean ticks, resets, forced histories and music tracks, in any
//! order. `run_ops` checks the session contract against a shadow session
//! (docs/ROBUSTNESS.md §2) and panics on a violation.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use duolando_gen::fixture::{tiny2_clip, tiny2_model};
use duolando_gen::session::{run_ops, SessionInput};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let Ok(input) = SessionInput::arbitrary(&mut u) else { return };
    let _ = run_ops(tiny2_model(), tiny2_clip(), &input);
});
