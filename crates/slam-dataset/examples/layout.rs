//! Make a derived layout of an odometry sequence (`slam_dataset::layout`): its frames driven there and
//! back, or with a standstill, as a sequence of their own that `slam-app run` and `track-bench --case`
//! take like any other.
//!
//! ```text
//! cargo run --release -p slam-dataset --example layout -- there-and-back SEQUENCE OUT [LEGS]
//! cargo run --release -p slam-dataset --example layout -- standstill SEQUENCE OUT FRAME EXTRA
//! cargo run --release -p slam-dataset --example layout -- reversed SEQUENCE OUT
//! ```
//! `SEQUENCE` is an odometry `sequences/NN` folder; the new sequence is `OUT/sequences/NN` (its poses in
//! `OUT/poses/NN.txt`). `tools/layout.sh` runs this.

use std::{path::PathBuf, process::ExitCode};

use slam_dataset::layout::{write_layout, Order};

fn usage() -> ExitCode {
    eprintln!(
        "usage: layout there-and-back SEQUENCE OUT [LEGS (default 5)]\n       layout standstill SEQUENCE OUT FRAME EXTRA\n       layout reversed SEQUENCE OUT"
    );
    ExitCode::from(2)
}

fn number(what: &str, text: &str) -> Result<usize, String> {
    text.parse().map_err(|_| format!("{what} '{text}' is not a whole number"))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let order = match (args.first().map(String::as_str), args.len()) {
        (Some("there-and-back"), 3) => Ok(Order::ThereAndBack { legs: 5 }),
        (Some("there-and-back"), 4) => number("LEGS", &args[3]).map(|legs| Order::ThereAndBack { legs }),
        (Some("reversed"), 3) => Ok(Order::Reversed),
        (Some("standstill"), 5) => number("FRAME", &args[3])
            .and_then(|at| number("EXTRA", &args[4]).map(|extra| Order::Standstill { at, extra })),
        _ => return usage(),
    };
    let order = match order {
        Ok(o) => o,
        Err(e) => {
            eprintln!("layout: {e}");
            return ExitCode::from(2);
        }
    };
    match write_layout(&PathBuf::from(&args[1]), order, &PathBuf::from(&args[2])) {
        Ok(dir) => {
            println!("{}", dir.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("layout: {e}");
            ExitCode::FAILURE
        }
    }
}
