use crate::arena::{Arena, ArenaError, Carve, Planner, ALIGN};

fn carve<'a, C: Carve<'a>>(c: &mut C) -> Result<(&'a mut [f32], &'a mut [u32], &'a mut [f32]), ArenaError> {
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
