//! `marionette take`, `replay` and `show` refuse bad files with the file,
//! the field and the reason, and never panic (#17).

use std::process::{Command, Output};

fn marionette(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .output()
        .expect("marionette runs")
}

fn fails(args: &[&str]) -> String {
    let out = marionette(args);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {out:?}");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn bad_takes_are_refused_by_every_command_that_reads_them() {
    use marionette_host::take::{Event, Take};
    let dir = tempfile::tempdir().unwrap();
    let take = Take {
        channels: 1,
        period_us: 1000,
        region: vec![1, 2, 3],
        source: "t".into(),
        events: vec![Event::output(0, true, &[6000])],
    };
    let bytes = take.to_bytes().unwrap();
    let cut = dir.path().join("cut.take");
    std::fs::write(&cut, &bytes[..bytes.len() - 3]).unwrap();
    let flipped = dir.path().join("flip.take");
    let mut b = bytes.clone();
    b[20] ^= 0x10;
    std::fs::write(&flipped, &b).unwrap();
    let not_a_take = dir.path().join("x.take");
    std::fs::write(&not_a_take, b"MREG\x01\x00\x00\x00").unwrap();
    let out = dir.path().join("o.bin");
    let o = out.to_str().unwrap();
    for (file, why) in [
        (&cut, "CRC mismatch"),
        (&flipped, "CRC mismatch"),
        (&not_a_take, "not a take"),
    ] {
        let f = file.to_str().unwrap();
        for args in [
            vec!["take", "info", f],
            vec!["take", "export", f, "--csv", o],
            vec!["take", "edit", f, "-o", o, "--time-scale", "2"],
            vec!["replay", f, "--emulated"],
            vec!["show", "build", f, "-o", o],
        ] {
            let err = fails(&args);
            assert!(err.contains(f) && err.contains(why), "{args:?}: {err}");
        }
    }
    // A valid take whose region holds no rig: refused, not a panic.
    let no_rig = dir.path().join("norig.take");
    std::fs::write(&no_rig, &bytes).unwrap();
    let err = fails(&["show", "build", no_rig.to_str().unwrap(), "-o", o]);
    assert!(err.contains("no valid rig"), "{err}");
    assert!(!out.exists(), "nothing written");
}
