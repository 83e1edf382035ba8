//! Make a raw rig's recording from a rectified KITTI odometry sequence (`slam_runner::raw_rig`):
//!
//! ```sh
//! cargo run --release -p slam-runner --example raw_rig -- fixtures/kitti_odom_06/sequences/06 out/raw06 [FRAMES]
//! cargo run --release -p slam-app -- run out/raw06 --calib out/raw06/camchain.yaml --out out/raw06-kalibr
//! ```

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(seq), Some(out)) = (args.first(), args.get(1)) else {
        eprintln!("usage: raw_rig KITTI_ODOMETRY_SEQUENCE OUT [FRAMES]");
        return std::process::ExitCode::from(2);
    };
    let frames = match args.get(2).map(|f| f.parse::<usize>()) {
        Some(Ok(n)) => Some(n),
        Some(Err(e)) => {
            eprintln!("FRAMES: {e}");
            return std::process::ExitCode::from(2);
        }
        None => None,
    };
    let spec = slam_runner::raw_rig::RawRigSpec::default();
    match slam_runner::raw_rig::write_raw_rig(seq.as_ref(), out.as_ref(), frames, &spec) {
        Ok(rig) => {
            println!(
                "wrote {} frames into {}: {} and {}",
                rig.frames,
                rig.dir.display(),
                rig.kalibr.display(),
                rig.orbslam.display()
            );
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
