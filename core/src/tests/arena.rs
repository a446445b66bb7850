use crate::arena::{Arena, ArenaError, Carve, Planner, Split, ALIGN};

fn carve<'a, C: Carve<'a>>(
    c: &mut C,
) -> Result<(&'a mut [f32], &'a mut [u32], &'a mut [f32]), ArenaError> {
    Ok((c.f32(3)?, c.u32(17)?, c.f32(100)?))
}

#[test]
fn planner_matches_arena_and_fails_one_byte_short() {
    let mut p = Planner::new();
    carve(&mut p).unwrap();
    assert_eq!(p.bytes(), 64 + 128 + 448);
    let total = p.total_for_any_base().unwrap();
    for offset in 0..ALIGN {
        let mut buf = vec![0u8; total + 2 * ALIGN];
        let base = (ALIGN - buf.as_ptr() as usize % ALIGN) % ALIGN;
        let slice = &mut buf[base + offset..base + offset + total];
        let mut a = Arena::new(slice);
        let (x, y, z) = carve(&mut a).unwrap();
        assert_eq!((x.len(), y.len(), z.len()), (3, 17, 100));
        assert_eq!(x.as_ptr() as usize % ALIGN, 0);
        assert_eq!(z.as_ptr() as usize % ALIGN, 0);
        assert!(a.used() <= total);
    }
    // Aligned base: exactly p.bytes() needed; one byte less fails.
    let mut buf = vec![0u8; total + ALIGN];
    let base = (ALIGN - buf.as_ptr() as usize % ALIGN) % ALIGN;
    let mut a = Arena::new(&mut buf[base..base + p.bytes()]);
    carve(&mut a).unwrap();
    assert_eq!(a.used(), p.bytes());
    let mut a = Arena::new(&mut buf[base..base + p.bytes() - 1]);
    assert!(matches!(carve(&mut a), Err(ArenaError::OutOfMemory { .. })));
    let mut a = Arena::new(&mut buf[..]);
    assert_eq!(a.f32(usize::MAX / 2).unwrap_err(), ArenaError::Overflow);
}

/// A `Split` pool of `floats_for(plan)` floats fits what the plan counted
/// (pieces rounded like the arena's, so an aligned pool gives aligned
/// pieces), one piece less of room fails with `OutOfMemory`, pieces do not
/// zero (a phase sees the previous phase's values), integer pieces included.
#[test]
fn split_pool_fits_its_plan_and_does_not_zero() {
    let pieces = |c: &mut Split<'_>| -> Result<usize, ArenaError> {
        let (a, b, d) = (c.f32(3)?, c.f32(100)?, c.f32(16)?);
        assert_eq!((a.len(), b.len(), d.len()), (3, 100, 16));
        assert_eq!(b.as_ptr() as usize - a.as_ptr() as usize, 64);
        assert_eq!(d.as_ptr() as usize - b.as_ptr() as usize, 448);
        Ok(d[0].to_bits() as usize)
    };
    let mut p = Planner::new();
    for n in [3, 100, 16] {
        p.f32(n).unwrap();
    }
    let n = Split::floats_for(&p);
    assert_eq!(n, (64 + 448 + 64) / 4);
    let mut pool = vec![7.0f32; n];
    assert_eq!(
        pieces(&mut Split::new(&mut pool)).unwrap(),
        7.0f32.to_bits() as usize
    );
    assert!(matches!(
        pieces(&mut Split::new(&mut pool[..n - 1])),
        Err(ArenaError::OutOfMemory { .. })
    ));
    // Integer pieces: the pool's floats viewed as integers, rounded as a
    // plan counts them (an int8 panel: values, scales, corrections).
    let ints = |c: &mut Split<'_>| -> Result<(usize, usize, usize, usize), ArenaError> {
        let (q, d, k, h) = (c.i8(33)?, c.f32(2)?, c.i32(4)?, c.u16(31)?);
        assert_eq!((q.len(), d.len(), k.len(), h.len()), (33, 2, 4, 31));
        assert_eq!(d.as_ptr() as usize - q.as_ptr() as usize, 64);
        Ok((
            q[0] as u8 as usize,
            k[0] as u32 as usize,
            h[0] as usize,
            h.as_ptr() as usize - k.as_ptr() as usize,
        ))
    };
    let mut p = Planner::new();
    let _ = (
        p.i8(33).unwrap(),
        p.f32(2).unwrap(),
        p.i32(4).unwrap(),
        p.u16(31).unwrap(),
    );
    let n = Split::floats_for(&p);
    assert_eq!(n, 4 * 64 / 4);
    let mut pool = vec![7.0f32; n];
    let bits = 7.0f32.to_bits();
    assert_eq!(
        ints(&mut Split::new(&mut pool)).unwrap(),
        (
            (bits & 0xff) as usize,
            bits as usize,
            (bits & 0xffff) as usize,
            64
        )
    );
    assert!(matches!(
        ints(&mut Split::new(&mut pool[..n - 1])),
        Err(ArenaError::OutOfMemory { .. })
    ));
}
