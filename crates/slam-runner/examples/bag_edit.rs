//! A bag made from another (`slam_runner::bag_edit`): `--png` re-encodes raw images as PNG
//! CompressedImage messages, `--repeat N` plays the bag N times in a row with its stamps moved on.
//!
//! ```sh
//! cargo run --release -p slam-runner --example bag_edit -- IN.mcap OUT.mcap [--png] [--repeat N]
//! ```

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(input), Some(output)) = (args.first(), args.get(1)) else {
        eprintln!("usage: bag_edit IN.mcap OUT.mcap [--png] [--repeat N]");
        return std::process::ExitCode::from(2);
    };
    let png = args.iter().any(|a| a == "--png");
    let repeat = match args.iter().position(|a| a == "--repeat").map(|i| args.get(i + 1).map(|n| n.parse::<usize>())) {
        None => 1,
        Some(Some(Ok(n))) if n >= 1 => n,
        _ => {
            eprintln!("--repeat takes a count of at least 1");
            return std::process::ExitCode::from(2);
        }
    };
    let edit = slam_runner::bag_edit::BagEdit { png, repeat };
    match slam_runner::bag_edit::edit_bag(input.as_ref(), output.as_ref(), edit) {
        Ok(n) => {
            println!("wrote {n} messages into {output}");
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
