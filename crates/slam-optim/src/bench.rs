//! Helpers for benchmark commands (`slam-app optim-bench`): process CPU time and peak memory from
//! Linux's `/proc`, and the generated bundle adjustment used to compare the dense and sparse paths of
//! the reduced system. Nothing here is used by the solvers.

use crate::{conformance, Graph, Values};

/// CPU time (user + system) this process has used, in seconds, from `/proc/self/stat` (clock ticks
/// of 10 ms); `None` where `/proc` is not available. Steadier than wall time on a loaded machine.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // the fields after the command name, which is in parentheses and may hold spaces
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// A `kB` field of `/proc/self/status` (`VmHWM`: peak resident memory; `VmRSS`: current), in KiB.
pub fn status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status.lines().find_map(|l| {
        let rest = l.strip_prefix(field)?.strip_prefix(':')?;
        rest.split_whitespace().next()?.parse().ok()
    })
}

/// A seeded stereo bundle adjustment along a 1 m-per-frame path: `n_poses` SE(3) cameras (the first
/// two fixed, the rest perturbed by ~5 cm / 0.2°), `points_per_pose` points per camera seen by it and
/// the next three (0.5 px noise, Huber), points marked for elimination. The reduced system has
/// `6 (n_poses − 2)` unknowns in a band; above the dense limit (2 000 unknowns, 336 poses) the sparse
/// path is taken. The same generator as [`conformance::check_sparse_matches_dense`].
pub fn generated_ba(n_poses: usize, points_per_pose: usize, seed: u64) -> (Values, Graph) {
    conformance::generated_stereo_ba(n_poses, points_per_pose, seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_readings_are_plausible() {
        if !std::path::Path::new("/proc/self/status").exists() {
            return; // not Linux
        }
        let cpu = process_cpu_seconds().expect("cpu time");
        assert!((0.0..1e6).contains(&cpu));
        // the current size first: reading the file may grow it, and the peak read after covers that
        let now = status_kib("VmRSS").expect("VmRSS");
        let peak = status_kib("VmHWM").expect("VmHWM");
        assert!(peak >= now && now > 0, "peak {peak} KiB, now {now} KiB");
        assert_eq!(status_kib("NoSuchField"), None);
    }

    #[test]
    fn generated_ba_is_above_the_dense_limit_and_seeded() {
        let (v, g) = generated_ba(400, 2, 5);
        let (v2, g2) = generated_ba(400, 2, 5);
        assert_eq!(v, v2);
        assert_eq!(g.len(), g2.len());
        let sys = crate::linear::LinearSystem::new(&g, &v, crate::Options::default().dense_limit).expect("layout");
        assert_eq!(sys.reduced_dim(), 6 * 398);
        assert!(sys.is_sparse());
    }
}
