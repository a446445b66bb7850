//! `duolando synth` output: the DD100 layout, shapes, split and determinism.

use duolando::npy::read_f32_2d;
use duolando::synth::dataset::{plan_takes, write_dataset};

#[test]
fn dataset_layout_shapes_split_and_determinism() {
    let dir = std::env::temp_dir().join(format!("duo-synth-{}", std::process::id()));
    let minutes = 4.0;
    let summary = write_dataset(&dir, minutes, 3, None, |_, _| {}).unwrap();
    assert!(summary.seconds >= minutes * 60.0, "{} s", summary.seconds);
    let entries = plan_takes(minutes, 3, None);
    assert_eq!(entries.len(), summary.takes);
    assert!(
        entries.iter().any(|e| e.split == "test") && entries.iter().any(|e| e.split == "train")
    );
    for e in &entries {
        // The original split rule on the file name.
        let idx: usize = e.stem.split('_').nth(1).unwrap().parse().unwrap();
        assert_eq!(e.split == "test", idx % 5 == 0, "{}", e.stem);
        let pos = |s: &str| {
            dir.join("motion/pos3d")
                .join(e.split)
                .join(format!("{}{s}.npy", e.stem))
        };
        let f = read_f32_2d(&pos("_00"), Some(165), "follower").unwrap();
        let l = read_f32_2d(&pos("_01"), Some(165), "leader").unwrap();
        let r = read_f32_2d(
            &dir.join("motion/rotmat")
                .join(e.split)
                .join(format!("{}_01.npy", e.stem)),
            Some(498),
            "rotmat",
        )
        .unwrap();
        let m = read_f32_2d(
            &dir.join("music/feature")
                .join(e.split)
                .join(format!("{}.npy", e.stem)),
            Some(54),
            "music",
        )
        .unwrap();
        assert!(f.rows == l.rows && l.rows == r.rows && r.rows == m.rows && f.rows > 200);
        // rotmat's root translation is the pelvis of pos3d.
        assert_eq!(&r.data[0..3], &l.data[0..3]);
    }
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("takes.json")).unwrap()).unwrap();
    assert_eq!(index["takes"].as_array().unwrap().len(), entries.len());
    assert!(dir.join("README.md").exists());
    // Same seed, same bytes.
    let first = std::fs::read(dir.join("takes.json")).unwrap();
    let some = &entries[0];
    let p = dir
        .join("motion/rotmat")
        .join(some.split)
        .join(format!("{}_00.npy", some.stem));
    let bytes = std::fs::read(&p).unwrap();
    write_dataset(&dir, minutes, 3, None, |_, _| {}).unwrap();
    assert_eq!(std::fs::read(dir.join("takes.json")).unwrap(), first);
    assert_eq!(std::fs::read(&p).unwrap(), bytes);
    std::fs::remove_dir_all(&dir).ok();
}
