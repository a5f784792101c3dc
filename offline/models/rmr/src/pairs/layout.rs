//! The joints RMR reads (lower body, feet), the ground root and foot contacts (RMR sec. 4):
//! defined in the core layer ([`zoo_protocol::stitch`]), which the engine's runtime shares, and
//! re-exported here for the offline tools.

pub use zoo_protocol::stitch::{
    BANDAI2_CONTACTS, BANDAI2_LOWER_BODY, CONTACT_THRESHOLDS, GroundRoot, LayoutError, StitchLayout, ground_roots,
};

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    #[test]
    fn root_algebra_round_trips() {
        let a = GroundRoot { pos: DVec3::new(3.0, 0.0, -2.0), yaw: 0.7 };
        let b = GroundRoot { pos: DVec3::new(-1.0, 0.0, 5.0), yaw: -2.1 };
        let p = DVec3::new(0.3, 1.5, -0.8);
        assert!((a.compose(&b).to_world(p) - a.to_world(b.to_world(p))).length() < 1e-12);
        let id = a.compose(&a.inverse());
        assert!(id.pos.length() < 1e-12 && id.yaw.abs() < 1e-12);
        assert!((a.to_local(a.to_world(p)) - p).length() < 1e-12);
        assert!((a.rotation() * DVec3::Z - a.forward()).length() < 1e-12);
    }

    #[test]
    fn root_of_hips_projects_and_takes_the_heading() {
        let skeleton = zoo_data::synth::skeleton();
        let layout = StitchLayout::bandai2(&skeleton).unwrap();
        // Synthetic rest frame of the hips (local X up, local Z forward), turned by 0.4 rad.
        let hips = DQuat::from_rotation_y(0.4) * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let r = layout.root_of(hips, DVec3::new(1.0, 90.0, 2.0));
        assert_eq!(r.pos, DVec3::new(1.0, 0.0, 2.0));
        assert!((r.yaw - 0.4).abs() < 1e-12, "{}", r.yaw);
    }

    #[test]
    fn bandai2_layout_names_and_bad_rigs() {
        let mut skeleton = zoo_data::synth::skeleton();
        let layout = StitchLayout::bandai2(&skeleton).unwrap();
        assert_eq!(layout.lower_body.len(), 9);
        assert_eq!(layout.upper_body(21).len(), 12);
        assert_eq!(layout.contacts, [15, 16, 19, 20]);
        skeleton.names[16] = "LeftToeBase".into();
        let err = StitchLayout::bandai2(&skeleton).unwrap_err().to_string();
        assert!(err.contains("Toes_L"), "{err}");
        let bad = StitchLayout { lower_body: vec![1, 2], ..layout.clone() };
        assert!(bad.validate(&zoo_data::synth::skeleton()).unwrap_err().to_string().contains("joint 0"));
        let bad = StitchLayout { contacts: [15, 16, 19, 40], ..layout };
        assert!(bad.validate(&zoo_data::synth::skeleton()).unwrap_err().to_string().contains("40"));
    }

    #[test]
    fn contacts_use_each_joints_threshold() {
        let layout = StitchLayout::bandai2(&zoo_data::synth::skeleton()).unwrap();
        let mut frame = vec![DVec3::ZERO; 21];
        frame[15].y = 11.7 + 2.4; // heel below 2.5
        frame[16].y = 4.3 + 1.7; // toe above 1.6
        frame[19].y = 11.7 + 2.6;
        frame[20].y = 4.3 + 1.5;
        assert_eq!(layout.contacts_of(&frame), [true, false, false, true]);
    }
}
