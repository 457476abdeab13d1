//! `marionette live` as a VMC sender would drive it: 300 frames of the
//! bundled recording (`data/recordings/reach_hdm05_007.csv`, every 4th
//! frame, 200 a second) sent over loopback UDP as VMC bundles (the pelvis
//! as the `Hips` bone, the palms as `RightHand`/`LeftHand` bones relative
//! to it, all in Unity's left-handed frame, converted here independently
//! of the code under test), from 127.0.0.2, with garbage packets mixed in;
//! a second sender on 127.0.0.3 is not in `--allow`. `live` forwards to
//! the emulated board (QEMU, tracker UART on a pty); its servo output must
//! equal the core run on the session `live` recorded.

use glam::{DQuat, DVec3};
use marionette_core::wire::Message;
use marionette_host::cmd::live::{self, Args, Listener};
use marionette_host::import::{self, csv::TrackerSample};
use marionette_host::perform::{self, Framing};
use marionette_tests::puppet::{humanoid16, repo, rest_table};
use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Marionette's right-handed Y-up frame to Unity's: X mirrored, a
/// quaternion's y and z negated (the mirror is its own inverse).
fn to_unity(p: DVec3, q: DQuat) -> ([f32; 3], [f32; 4]) {
    (
        [-p.x as f32, p.y as f32, p.z as f32],
        [q.x as f32, -q.y as f32, -q.z as f32, q.w as f32],
    )
}

fn pose(addr: &str, name: &str, (p, q): ([f32; 3], [f32; 4])) -> OscPacket {
    let mut args = vec![OscType::String(name.into())];
    args.extend(p.iter().chain(&q).map(|&x| OscType::Float(x)));
    OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    })
}

/// One recorded time step (sensors 0 right palm, 1 left palm, 2 pelvis) as
/// a VMC bundle: the root at the origin, the hips at the pelvis, each hand
/// as a bone of the hips (the bones between are not sent).
fn vmc_bundle(step: &[TrackerSample]) -> Vec<u8> {
    let by = |id: u8| step.iter().find(|s| s.sensor == id).unwrap();
    let hips = by(2);
    let local = |s: &TrackerSample| {
        let inv = hips.orientation.inverse();
        (inv * (s.position - hips.position), inv * s.orientation)
    };
    let (rp, rq) = local(by(0));
    let (lp, lq) = local(by(1));
    let content = vec![
        pose(
            "/VMC/Ext/Root/Pos",
            "root",
            ([0.0; 3], [0.0, 0.0, 0.0, 1.0]),
        ),
        pose(
            "/VMC/Ext/Bone/Pos",
            "Hips",
            to_unity(hips.position, hips.orientation),
        ),
        pose("/VMC/Ext/Bone/Pos", "RightHand", to_unity(rp, rq)),
        pose("/VMC/Ext/Bone/Pos", "LeftHand", to_unity(lp, lq)),
        OscPacket::Message(OscMessage {
            addr: "/VMC/Ext/OK".into(),
            args: vec![OscType::Int(1)],
        }),
    ];
    rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content,
    }))
    .unwrap()
}

fn sender(ip: [u8; 4]) -> UdpSocket {
    UdpSocket::bind(SocketAddr::new(IpAddr::V4(Ipv4Addr::from(ip)), 0)).unwrap()
}

#[test]
fn vmc_over_udp_drives_the_emulated_board_as_sim_on_the_recorded_session() {
    let dir = tempfile::tempdir().unwrap();
    let tables = dir.path().join("rest.bin");
    std::fs::write(&tables, rest_table(&humanoid16())).unwrap();
    let samples =
        import::csv::read_tracker_csv(&repo().join("data/recordings/reach_hdm05_007.csv")).unwrap();
    let steps: Vec<Vec<TrackerSample>> = samples
        .chunk_by(|a, b| a.time_us == b.time_us)
        .step_by(4)
        .take(300)
        .map(<[TrackerSample]>::to_vec)
        .collect();
    assert_eq!(steps.len(), 300);

    let args = Args {
        rig: repo().join("rigs/humanoid16.toml"),
        tables: vec![tables],
        port: None,
        baud: None,
        listen: "127.0.0.1:0".parse().unwrap(),
        allow: vec!["127.0.0.2".parse().unwrap()],
        silence_ms: 500,
        seconds: None,
        frame: Framing::Compact,
        out: dir.path().join("out"),
        take: Some(dir.path().join("live.take")),
        json: true,
        view: Default::default(),
    };
    let listener = Listener::bind(args.listen).unwrap();
    let to = listener.local_addr().unwrap();
    let stop = AtomicBool::new(false);
    let (summary, replies) = std::thread::scope(|scope| {
        let run = scope.spawn(|| live::live(&args, &listener, &stop));
        // `live` creates its recording once the board has armed.
        let deadline = Instant::now() + Duration::from_secs(120);
        while !args.out.join("live.csv").exists() {
            assert!(
                Instant::now() < deadline && !run.is_finished(),
                "live never armed"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let allowed = sender([127, 0, 0, 2]);
        let stranger = sender([127, 0, 0, 3]);
        let garbage: [&[u8]; 3] = [
            b"\x00\x01 not OSC",
            b"#bundle\0\0\0\0\0\0\0\0\x01\0\0\0\x40/VMC",
            // A bone message with too few arguments.
            b"/VMC/Ext/Bone/Pos\0\0\0,sf\0Hips\0\0\0\0\x3f\x80\0\0",
        ];
        let start = Instant::now();
        for (i, step) in steps.iter().enumerate() {
            let due = Duration::from_millis(5 * i as u64);
            std::thread::sleep(due.saturating_sub(start.elapsed()));
            allowed.send_to(&vmc_bundle(step), to).unwrap();
            if i % 50 == 25 {
                allowed.send_to(garbage[(i / 50) % 3], to).unwrap();
            }
            if i % 15 == 0 {
                // Valid VMC, the wrong sender: never forwarded.
                stranger.send_to(&vmc_bundle(&steps[0]), to).unwrap();
            }
        }
        // Silent longer than --silence-ms, then stop.
        std::thread::sleep(Duration::from_millis(1000));
        stop.store(true, Ordering::Relaxed);
        run.join().unwrap().expect("live runs")
    });

    assert_eq!(summary.refused, 20);
    assert_eq!(summary.refused_from, ["127.0.0.3"]);
    assert_eq!(summary.senders.len(), 1);
    assert!(summary.senders[0].starts_with("127.0.0.2:"));
    assert_eq!(summary.source.malformed, 6);
    assert_eq!(summary.source.packets, 306);
    assert_eq!(summary.silences, 1);
    let c = &summary.board.sender;
    println!(
        "live: {} of {} frames sent, {} dropped, {:.0} B/s of {:.0}; {} telemetry",
        c.sent,
        c.offered,
        c.dropped,
        summary.board.link_bytes_per_s,
        summary.board.link_capacity_bytes_per_s,
        summary.board.telemetry
    );
    assert!(summary.board.disarm_acked);
    assert_eq!(c.offered, 300);
    assert_eq!(c.sent + c.dropped, 300);
    assert!(c.sent >= 100, "{c:?}");

    // The recording is what was sent: its first frame is one of the first
    // steps (a busy writer may have had a newer one by then), its last the
    // last step (nothing came to replace it), through VMC and back.
    let recorded = import::csv::read_tracker_csv(&args.out.join("live.csv")).unwrap();
    let frames = perform::frames(&recorded).unwrap();
    assert_eq!(frames.len() as u64, c.sent);
    let matches = |frame: &marionette_core::wire::TrackerFrame, step: &[TrackerSample]| {
        frame.sensors.as_slice().len() == 3
            && frame.sensors.as_slice().iter().all(|s| {
                let want = step.iter().find(|w| w.sensor == s.id).unwrap();
                let got = DVec3::from(s.position.map(f64::from));
                let [w, x, y, z] = s.rotation.map(f64::from);
                (got - want.position).length() < 1e-5
                    && DQuat::from_xyzw(x, y, z, w).dot(want.orientation).abs() > 1.0 - 1e-6
            })
    };
    assert!(steps[..10].iter().any(|step| matches(&frames[0], step)));
    assert!(matches(frames.last().unwrap(), &steps[299]));

    // The servo bytes equal the core run on the recorded session.
    let region = std::fs::read(args.out.join("region.bin")).unwrap();
    let session = perform::session(&frames).unwrap();
    let servo = std::fs::read(args.out.join("servo_live.bin")).unwrap();
    let outputs = perform::decode_maestro(&servo, 16);
    let followed = perform::follow(&region, &session, &outputs, &replies).unwrap();
    assert_eq!(followed.run.frame_targets.len(), frames.len());
    assert!(followed.compared >= frames.len());
    assert_eq!(followed.mismatches, 0, "trips {:?}", followed.trips);
    let checked = summary.emulated.as_ref().unwrap();
    assert_eq!(
        (checked.compared, checked.mismatches),
        (followed.compared, 0)
    );
    // The take (#17) holds the session sent and the board's servo outputs.
    let take = marionette_host::take::Take::load(&dir.path().join("live.take")).unwrap();
    assert_eq!(take.source, "live");
    assert_eq!(take.info().sent.tracker_frames, frames.len());
    let taken: Vec<Vec<u16>> = take.outputs().into_iter().map(|o| o.2).collect();
    assert_eq!(taken, outputs);
    let errors = replies.iter().rev().find_map(|m| match m {
        Message::Telemetry(t) => Some(t.errors.total()),
        _ => None,
    });
    assert_eq!(errors, Some(0));
}
