use super::*;
use crate::duolando::presets::duolando_published;

/// Geometries beyond the fixtures': stride 4, three stages, deep resnets.
fn configs() -> [VqConfig; 4] {
    let p = duolando_published().parts[0];
    [
        p,
        VqConfig { depth: 2, ..p },
        VqConfig {
            stride_t: 4,
            down_t: 1,
            ..p
        },
        VqConfig {
            down_t: 3,
            depth: 4,
            dilation_growth_rate: 2,
            ..p
        },
    ]
}

/// The simulation is long enough: twice as many pushes change no size
/// and no future_max.
#[test]
fn simulation_reaches_the_steady_state() {
    for cfg in configs() {
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            let g = Geometry::new(&cfg, kind).unwrap();
            let f = future_max_of(&g);
            let (mut c, m, last) = (Counts::ZERO, g.out_per_push, g.n_units - 1);
            let mut f2 = 0;
            for p in 1..=4 * g.sim_pushes(0) {
                c.advance(&g);
                f2 = f2.max(p.saturating_sub(c.set[last] / m));
            }
            assert_eq!(f, f2, "{kind:?} {cfg:?}");
            for lag in 0..=f + 1 {
                let n = g.sim_pushes(lag);
                let a = StackPlan::simulate_for(g.clone(), lag, lag, n);
                let b = StackPlan::simulate_for(g.clone(), lag, lag, 3 * n);
                assert_eq!(a, b, "{kind:?} lag {lag} {cfg:?}");
            }
            let a = StackPlan::simulate_for(g.clone(), 0, f, g.sim_pushes(f));
            let b = StackPlan::simulate_for(g.clone(), 0, f, 3 * g.sim_pushes(f));
            assert_eq!(a.scratch_need(), b.scratch_need());
        }
    }
}

/// Above future_max the output ring grows by one token per extra lag,
/// exactly what a simulation at that lag measures.
#[test]
fn out_ring_above_future_max() {
    for cfg in configs() {
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            let g = Geometry::new(&cfg, kind).unwrap();
            let f = future_max_of(&g);
            for lag in [f, f + 1, f + 5] {
                let sim = StackPlan::simulate(g.clone(), lag, lag);
                let plan = StackPlan::new(&cfg, kind, lag).unwrap();
                assert_eq!(sim.out_ring, plan.out_ring, "{kind:?} lag {lag}");
                assert_eq!(sim.ring, plan.ring);
            }
        }
    }
}

/// Configs outside the engine's limits: no plan, an arena error, no panic.
#[test]
fn invalid_configs_are_refused() {
    let p = duolando_published().parts[0];
    let bad = [
        VqConfig { depth: 0, ..p },
        VqConfig { stride_t: 3, ..p },
        VqConfig {
            width: u32::MAX,
            ..p
        },
        VqConfig {
            dilation_growth_rate: u32::MAX,
            ..p
        },
        VqConfig { down_t: 40, ..p },
        VqConfig { m_conv_den: 0, ..p },
    ];
    for cfg in bad {
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            assert_eq!(future_max(&cfg, kind), 0);
            assert!(StackPlan::new(&cfg, kind, 3).is_none());
            let mut pl = crate::arena::Planner::new();
            assert!(StreamStack::carve(&mut pl, &cfg, kind, 3).is_err());
        }
    }
    let mut pl = crate::arena::Planner::new();
    assert!(StreamStack::carve(&mut pl, &p, StackKind::Decoder, usize::MAX).is_err());
}

/// Index arithmetic of the units against brute force over the kernel taps.
#[test]
fn unit_reads_match_brute_force() {
    let units = [
        Unit::conv(4, 2, 1, 1, 1, 1),
        Unit::conv(8, 4, 2, 1, 1, 1),
        Unit::res(9, 1),
        Unit::convt(2, 1, 1),
        Unit::convt(4, 1, 1),
    ];
    for u in units {
        for t in 0..40usize {
            let reads: std::vec::Vec<isize> = match u.kind {
                UnitKind::ConvT => (-10..60)
                    .filter(|&i| {
                        (0..u.kernel as isize)
                            .any(|j| i * u.stride as isize - u.pad as isize + j == t as isize)
                    })
                    .collect(),
                _ => (0..u.kernel)
                    .map(|j| (t * u.stride + j * u.dilation) as isize - u.pad as isize)
                    .collect(),
            };
            assert_eq!(u.first_in(t), *reads.iter().min().unwrap(), "{u:?} t {t}");
            assert_eq!(u.last_in(t), *reads.iter().max().unwrap(), "{u:?} t {t}");
        }
    }
}
