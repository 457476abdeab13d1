//! A VMC source for the host tests that drive `marionette live`.

use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};

/// A VMC bundle: the hips still, the right hand (a bone of the hips, in
/// Unity's frame) on a circle in front of them, `t` turns along.
pub fn vmc_hand(t: f64) -> Vec<u8> {
    let bone = |name: &str, v: [f32; 7]| {
        let mut args = vec![OscType::String(name.into())];
        args.extend(v.iter().map(|&x| OscType::Float(x)));
        OscPacket::Message(OscMessage {
            addr: "/VMC/Ext/Bone/Pos".into(),
            args,
        })
    };
    let a = (t * std::f64::consts::TAU) as f32;
    let hand = [
        0.25 + 0.15 * a.cos(),
        0.35 + 0.15 * a.sin(),
        0.25,
        0.0,
        0.0,
        0.0,
        1.0,
    ];
    rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content: vec![
            bone("Hips", [0.0, 0.9, 0.0, 0.0, 0.0, 0.0, 1.0]),
            bone("RightHand", hand),
        ],
    }))
    .unwrap()
}
