//! Smoke tests of the generators on the tiny2 fixture.
use duolando_gen::duo::{check_duo, DuoOutcome};
use duolando_gen::fixture::{tiny2_clip, tiny2_duo_bytes, tiny2_model};
use duolando_gen::session::{run_ops, ConfigGen, Field, FrameGen, Op, SeedGen, SessionInput};
use duolando_gen::floats::Hostile;

#[test]
fn fixture_model_binds() {
    assert_eq!(check_duo(tiny2_duo_bytes()), DuoOutcome::Bound);
}

#[test]
fn nan_leader_frame_is_refused_and_shadow_agrees() {
    let f = Field::In(0);
    let config = ConfigGen { lookahead: f, enc_future: f, dec_future: f, shift: Field::In(4), music_lookahead: f, lat_past: f, top_k: None, pending_frames: Field::In(64), music_buffer_frames: Field::In(64), staggered: false };
    let ops = vec![Op::Ticks(20), Op::Leader(FrameGen::Poke { at: 7, value: Hostile::Nan }), Op::Ticks(20), Op::PullAll];
    let rep = run_ops(tiny2_model(), tiny2_clip(), &SessionInput { config, seed: SeedGen::Clip, ops });
    assert_eq!(rep.non_finite_refused, 1);
    assert!(rep.pulled > 0 && rep.recovered > 0, "{rep:?}");
}
