//! Real BA and pose-graph problems (fixtures/optim): the anchors' initial costs and spot residuals are
//! reproduced exactly and malformed files are errors (the minima are in `slam_optim::conformance`, run by
//! every backend crate).

use std::path::PathBuf;

use slam_optim::io::{read_bal, read_g2o};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/optim").join(name)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn bal_initial_costs_and_spot_residuals() {
    for (file, l2, huber, r0) in [
        ("dubrovnik-3-7-pre.txt", 2.764220e+03, 2.359657e+02, [-8.013417270353, 7.900505424598]),
        ("problem-49-7776-pre.txt", 8.509125e+05, 1.206505e+05, [-9.020226301243, 11.263958304987]),
        ("problem-16-22106-pre.txt", 4.185660e+06, 5.225660e+05, [-8.013417270353, 7.900505424598]),
    ] {
        let p = read_bal(fixture(file), None).expect("reads");
        assert!(rel(p.graph.cost(&p.values).expect("cost"), l2) < 5e-7, "{file} L2");
        let r = p.graph.whitened_residual(0, &p.values).expect("factor 0").expect("evaluates");
        assert!((r[0] - r0[0]).abs() < 1e-9 && (r[1] - r0[1]).abs() < 1e-9, "{file}: {r}");
        let h = read_bal(fixture(file), Some(1.0)).expect("reads");
        assert!(rel(h.graph.cost(&h.values).expect("cost"), huber) < 5e-7, "{file} Huber");
    }
}

#[test]
fn pose_graph_initial_costs() {
    for (file, initial) in [("sphere2500.g2o", 1.305658e+06), ("parking-garage.g2o", 8.363602e+03)] {
        let p = read_g2o(fixture(file)).expect("reads");
        assert!(rel(p.graph.cost(&p.values).expect("cost"), initial) < 5e-7, "{file}");
    }
}

#[test]
fn malformed_problems_are_errors() {
    let dir = std::env::temp_dir().join(format!("optim-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    // huge declared counts with no data: an error, not an allocation of gigabytes (found by fuzzing)
    std::fs::write(dir.join("huge.txt"), "3 99999999999 99999999999\n0 0 1 2\n").expect("write");
    assert!(read_bal(dir.join("huge.txt"), None).is_err());
    std::fs::write(dir.join("bad.txt"), "1 1 1\n0 5 1.0 2.0\n").expect("write");
    let e = read_bal(dir.join("bad.txt"), None).err().expect("index out of range");
    assert!(e.to_string().contains("bad.txt"), "{e}");
    std::fs::write(dir.join("nan.txt"), "1 1 1\n0 0 nan 2.0\n").expect("write");
    assert!(read_bal(dir.join("nan.txt"), None).is_err());
    std::fs::write(
        dir.join("g.g2o"),
        "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n",
    )
    .expect("write");
    let e = read_g2o(dir.join("g.g2o")).err().expect("unknown vertex");
    assert!(e.to_string().contains("g.g2o:2"), "{e}");
    std::fs::write(dir.join("q.g2o"), "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n").expect("write");
    assert!(read_g2o(dir.join("q.g2o")).is_err());
    assert!(read_bal("/no/such/problem.txt", None).is_err());
}
