//! Synth determinism, shapes and plausibility figures.

use duolando::skeleton::{POS_DIM, ROT_DIM};
use duolando::synth::{demo_take, generate_take, Genre, Take, TakeSpec, MUSIC_DIM};

/// Planted ankles may move at most this much per frame (m).
const PLANTED_SPEED: f32 = 0.01;
/// Partner pelvis distance on the floor (m).
const PARTNER_MIN: f32 = 0.3;
const PARTNER_MAX: f32 = 0.6;
/// Joined hands (leader left wrist, follower right wrist) in closed hold (m).
const JOINED_HANDS: f32 = 0.12;

fn joint(pos: &[f32], t: usize, j: usize) -> [f32; 3] {
    let o = t * POS_DIM + 3 * j;
    [pos[o], pos[o + 1], pos[o + 2]]
}
fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Max ankle speed over frame pairs where the foot is planted in both.
fn max_planted_speed(take: &Take) -> f32 {
    let mut worst = 0.0f32;
    for tr in [&take.leader, &take.follower] {
        for t in 1..take.frames {
            for (k, ankle) in [(0, 7), (1, 8)] {
                if tr.contacts[t][k] && tr.contacts[t - 1][k] {
                    let v = dist(
                        joint(&tr.positions, t, ankle),
                        joint(&tr.positions, t - 1, ankle),
                    );
                    worst = worst.max(v);
                }
            }
        }
    }
    worst
}

fn partner_range(take: &Take) -> (f32, f32) {
    let (mut lo, mut hi) = (f32::MAX, 0.0f32);
    for t in 0..take.frames {
        let a = joint(&take.leader.positions, t, 0);
        let b = joint(&take.follower.positions, t, 0);
        let d = ((a[0] - b[0]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        lo = lo.min(d);
        hi = hi.max(d);
    }
    (lo, hi)
}

#[test]
fn shapes_and_finite_values() {
    let take = demo_take(3, 12.0);
    assert_eq!(take.frames, 360);
    for tr in [&take.leader, &take.follower] {
        assert_eq!(tr.positions.len(), take.frames * POS_DIM);
        assert_eq!(tr.rotmats.len(), take.frames * ROT_DIM);
        assert_eq!(tr.roots.len(), take.frames * 3);
        assert_eq!(tr.rotmat_with_root().len(), take.frames * (3 + ROT_DIM));
        assert!(tr
            .positions
            .iter()
            .chain(tr.rotmats.iter())
            .all(|v| v.is_finite()));
    }
    assert_eq!(take.music.len(), take.frames * MUSIC_DIM);
    assert!(take.music.iter().all(|v| v.is_finite()));
}

#[test]
fn same_seed_same_take_other_seed_other_take() {
    let a = demo_take(11, 6.0);
    let b = demo_take(11, 6.0);
    assert_eq!(a.leader.positions, b.leader.positions);
    assert_eq!(a.follower.rotmats, b.follower.rotmats);
    assert_eq!(a.music, b.music);
    let c = demo_take(12, 6.0);
    assert_ne!(a.leader.positions, c.leader.positions);
}

#[test]
fn every_genre_is_plausible() {
    let mut report = Vec::new();
    for (i, g) in Genre::ALL.iter().enumerate() {
        let take = generate_take(&TakeSpec {
            genre: *g,
            seconds: 30.0,
            bpm: None,
            beat_grid: None,
            choreo_seed: 100 + i as u64,
            take_seed: 7,
        });
        let (lo_bpm, hi_bpm) = g.bpm_range();
        assert!(
            take.bpm >= 72.0 && take.bpm <= 163.0 && take.bpm >= lo_bpm && take.bpm <= hi_bpm,
            "{g:?} {}",
            take.bpm
        );
        let speed = max_planted_speed(&take);
        let (lo, hi) = partner_range(&take);
        let contact_frac = take.leader.contacts.iter().filter(|c| c[0] && c[1]).count() as f32
            / take.frames as f32;
        let lowest_foot = [&take.leader, &take.follower]
            .iter()
            .flat_map(|tr| {
                (0..take.frames).flat_map(move |t| {
                    [
                        joint(&tr.positions, t, 10)[1],
                        joint(&tr.positions, t, 11)[1],
                    ]
                })
            })
            .fold(f32::MAX, f32::min);
        report.push(format!("{:<9} bpm {:5.1} figs {:2} planted-speed {:.5} m/f partner {:.3}..{:.3} m both-planted {:.2} lowest-toe {:.4} m",
            g.name(), take.bpm, take.figures.len(), speed, lo, hi, contact_frac, lowest_foot));
        assert!(
            speed < PLANTED_SPEED,
            "{g:?}: planted ankle moved {speed} m/frame"
        );
        assert!(
            lo >= PARTNER_MIN && hi <= PARTNER_MAX,
            "{g:?}: partner distance {lo}..{hi}"
        );
        assert!(
            lowest_foot > -0.005,
            "{g:?}: a foot went {lowest_foot} m below the floor"
        );
        assert!(
            take.figures.len() >= 3,
            "{g:?}: only {} figures",
            take.figures.len()
        );
        // The leader actually travels.
        let a = joint(&take.leader.positions, 0, 0);
        let travel: f32 = (1..take.frames)
            .map(|t| {
                dist(
                    joint(&take.leader.positions, t, 0),
                    joint(&take.leader.positions, t - 1, 0),
                )
            })
            .sum();
        assert!(
            travel > 1.0,
            "{g:?}: leader pelvis travelled only {travel} m from {a:?}"
        );
    }
    println!("{}", report.join("\n"));
}

#[test]
fn joined_hands_stay_together_in_closed_hold() {
    let take = generate_take(&TakeSpec {
        genre: Genre::Waltz,
        seconds: 30.0,
        bpm: Some(90.0),
        beat_grid: None,
        choreo_seed: 5,
        take_seed: 5,
    });
    let mut worst = 0.0f32;
    let mut n = 0;
    for f in take
        .figures
        .iter()
        .filter(|f| f.hold == duolando::synth::genre::Hold::Closed)
    {
        // Skip the hold blend at the figure start.
        for t in (f.start_frame + 15)..f.end_frame {
            let d = dist(
                joint(&take.leader.positions, t, 20),
                joint(&take.follower.positions, t, 21),
            );
            worst = worst.max(d);
            n += 1;
        }
    }
    println!("closed-hold frames {n}, worst joined-hand gap {worst:.3} m");
    assert!(n > 100);
    assert!(worst < JOINED_HANDS, "joined hands {worst} m apart");
}

#[test]
fn follower_answers_are_not_a_function_of_the_leader() {
    // Same choreography seed, different take seed: the leader's figures are
    // the same, the follower's hidden responses differ somewhere.
    let spec = |take_seed| TakeSpec {
        genre: Genre::Rumba,
        seconds: 40.0,
        bpm: None,
        beat_grid: None,
        choreo_seed: 9,
        take_seed,
    };
    let a = generate_take(&spec(1));
    let b = generate_take(&spec(2));
    let names = |t: &Take| t.figures.iter().map(|f| f.name).collect::<Vec<_>>();
    assert_eq!(names(&a), names(&b));
    assert_ne!(
        a.figures.iter().map(|f| f.response).collect::<Vec<_>>(),
        b.figures.iter().map(|f| f.response).collect::<Vec<_>>()
    );
    let diff = a
        .follower
        .positions
        .iter()
        .zip(&b.follower.positions)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    println!("max follower joint difference between takes: {diff:.3} m");
    assert!(diff > 0.1);
}

#[test]
fn music_beat_channel_matches_the_beat_grid() {
    let take = demo_take(4, 20.0);
    let hot: Vec<usize> = (0..take.frames)
        .filter(|&t| take.music[t * MUSIC_DIM + 53] == 1.0)
        .collect();
    let expect: Vec<usize> = take
        .beats
        .iter()
        .map(|b| (b * 30.0).round() as usize)
        .filter(|&f| f < take.frames)
        .collect();
    assert_eq!(hot, expect);
    // Onset envelope peaks at beats.
    for &f in &hot {
        let o = take.music[f * MUSIC_DIM + 52];
        let before = if f >= 3 {
            take.music[(f - 3) * MUSIC_DIM + 52]
        } else {
            0.0
        };
        assert!(o > before, "onset at beat frame {f}: {o} <= {before}");
    }
}

#[test]
fn a_beat_grid_puts_every_beat_on_a_bailando_token() {
    // 4 frames at 30 fps = one Bailando token (8 frames at 60 fps).
    let grid = 4.0 / 30.0;
    for (i, g) in Genre::ALL.iter().enumerate() {
        let spec = TakeSpec {
            genre: *g,
            seconds: 25.0,
            bpm: None,
            beat_grid: Some(grid),
            choreo_seed: 300 + i as u64,
            take_seed: 3,
        };
        let take = generate_take(&spec);
        let free = generate_take(&TakeSpec {
            beat_grid: None,
            ..spec
        });
        assert!(
            [150.0f32, 112.5, 90.0, 75.0]
                .iter()
                .any(|b| (take.bpm - b).abs() < 1e-3),
            "{}: {} BPM is not on the token grid",
            g.name(),
            take.bpm
        );
        // The tempo on the grid nearest the drawn one (one token per beat apart at most).
        let tokens = |bpm: f32| 60.0 / bpm / grid;
        assert!((tokens(take.bpm) - tokens(free.bpm)).abs() <= 0.5 + 1e-4);
        for b in &take.beats {
            let k = b / grid;
            assert!(
                (k - k.round()).abs() < 1e-3,
                "{}: beat at {b} s is off the grid",
                g.name()
            );
        }
        // The same figures, danced at the grid's tempo.
        let names = |t: &Take| t.figures.iter().map(|f| f.name).collect::<Vec<_>>();
        assert_eq!(names(&take)[..2], names(&free)[..2]);
    }
}
