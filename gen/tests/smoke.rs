//! Smoke tests of the generators on the tiny2 fixture.
use duolando_gen::duo::{
    check_duo, check_input, split, DuoInput, DuoOutcome, WeightEdit, NON_FINITE,
};
use duolando_gen::fixture::{
    btiny_duo_bytes, tiny2_clip, tiny2_duo_bytes, tiny2_model, transflower_duo_bytes,
};
use duolando_gen::floats::Hostile;
use duolando_gen::session::{run_ops, ConfigGen, Field, FrameGen, Op, SeedGen, SessionInput};

#[test]
fn fixture_model_binds() {
    assert_eq!(check_duo(tiny2_duo_bytes()), DuoOutcome::Bound);
    assert_eq!(check_duo(btiny_duo_bytes()), DuoOutcome::Bound);
    assert_eq!(check_duo(transflower_duo_bytes()), DuoOutcome::Bound);
}

/// Family edits: each base (Duolando, Bailando, Transflower) re-encoded as version 2 under every tag either
/// binds as its own family, or is refused (another family's tag, an
/// unknown tag) without a panic.
#[test]
fn family_tags_on_both_bases() {
    use duolando_core::format::FormatError;
    for (b, own) in [
        (split(tiny2_duo_bytes()), 0u8),
        (split(btiny_duo_bytes()), 1),
        (split(transflower_duo_bytes()), 2),
    ] {
        for tag in 0..6u8 {
            let out = check_input(
                &DuoInput::Family {
                    tag,
                    config: vec![],
                    bytes: vec![],
                },
                &b,
            );
            match tag {
                t if t == own => assert_eq!(out, DuoOutcome::Bound, "own tag {t}"),
                0..=2 => assert!(
                    matches!(out, DuoOutcome::Rejected(_)),
                    "tag {tag} on base {own}: {out:?}"
                ),
                t => assert_eq!(
                    out,
                    DuoOutcome::Rejected(FormatError::UnknownFamily { tag: t as u32 }),
                    "tag {t}"
                ),
            }
        }
    }
}

#[test]
fn nan_leader_frame_is_refused_and_shadow_agrees() {
    let f = Field::In(0);
    let config = ConfigGen {
        lookahead: f,
        enc_future: f,
        dec_future: f,
        shift: Field::In(4),
        music_lookahead: f,
        lat_past: f,
        top_k: None,
        pending_frames: Field::In(64),
        music_buffer_frames: Field::In(64),
        staggered: false,
    };
    let ops = vec![
        Op::Ticks(20),
        Op::Leader(FrameGen::Poke {
            at: 7,
            value: Hostile::Nan,
        }),
        Op::Ticks(20),
        Op::PullAll,
    ];
    let rep = run_ops(
        tiny2_model(),
        tiny2_clip(),
        &SessionInput {
            config,
            seed: SeedGen::Clip,
            ops,
        },
    );
    assert_eq!(rep.non_finite_refused, 1);
    assert!(rep.pulled > 0 && rep.recovered > 0, "{rep:?}");
}

/// The weight edits of the `duo_struct` fuzz target: every NaN / infinity
/// pattern is refused naming the first one, finite edge values are not.
#[test]
fn poisoned_weights_are_refused_by_name() {
    let base = split(tiny2_duo_bytes());
    let f32_entries: Vec<u16> = base
        .entries
        .iter()
        .enumerate()
        .filter(|(_, e)| e.dtype <= 1)
        .map(|(i, _)| i as u16)
        .collect();
    assert!(f32_entries.len() > 3, "tiny2 has float tensors");
    let (a, b) = (f32_entries[1], f32_entries[f32_entries.len() - 1]);
    for pattern in 0..10u8 {
        let edits = vec![
            WeightEdit {
                entry: b,
                element: 5,
                pattern,
            },
            WeightEdit {
                entry: a,
                element: 77,
                pattern,
            },
        ];
        let out = check_input(&DuoInput::Weights(edits), &base);
        assert_eq!(
            matches!(out, DuoOutcome::Rejected(_)),
            (pattern as usize) < NON_FINITE,
            "pattern {pattern}: {out:?}"
        );
    }
    // A NaN overwritten by a finite value is gone.
    let edits = vec![
        WeightEdit {
            entry: a,
            element: 3,
            pattern: 0,
        },
        WeightEdit {
            entry: a,
            element: 3,
            pattern: 7,
        },
    ];
    assert_eq!(
        check_input(&DuoInput::Weights(edits), &base),
        DuoOutcome::Bound
    );
}
