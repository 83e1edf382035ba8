//! A runtime library that exports ONNX Runtime's entry point but hands out no API table through it (its
//! `OrtGetApiBase` returns nothing; or its `GetApi` returns nothing for the API version asked while its
//! version string says 1.99.0): opening it is an error naming the library, not a panic inside the `ort`
//! crate. Its own process (a test file of its own): a library `ort` opened stays open for the process.
//! The two stand-ins are built here with the system's C compiler (`cc`, which Rust's linker needs too).

use std::{path::Path, process::Command};

use slam_detect::onnx::open_runtime;

/// Build `source` (C) as a shared library `name` in `dir`.
fn library(dir: &Path, name: &str, source: &str) -> std::path::PathBuf {
    let c = dir.join(format!("{name}.c"));
    std::fs::write(&c, source).expect("source");
    let so = dir.join(format!("lib{name}.so"));
    let built = Command::new("cc").args(["-shared", "-fPIC", "-o"]).arg(&so).arg(&c).status();
    assert!(built.is_ok_and(|s| s.success()), "cc builds {}", c.display());
    so
}

#[test]
fn a_library_without_an_api_table_is_refused_naming_it() {
    let dir = std::env::temp_dir().join(format!("ort-library-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let null = library(&dir, "nullbase", "const void* OrtGetApiBase(void) { return 0; }\n");
    let no_table = library(
        &dir,
        "notable",
        "struct Base { const void* (*GetApi)(unsigned); const char* (*GetVersionString)(void); };\n\
         static const void* get(unsigned v) { (void)v; return 0; }\n\
         static const char* version(void) { return \"1.99.0\"; }\n\
         static struct Base base = { get, version };\n\
         const struct Base* OrtGetApiBase(void) { return &base; }\n",
    );
    for lib in [&null, &no_table] {
        let e = open_runtime(lib).expect_err("no API table").to_string();
        assert!(
            e.contains(&lib.display().to_string()) && e.contains("does not load") && e.contains("no usable API table"),
            "{e}"
        );
    }
    // the library stays refused in this process, without a second attempt
    let e = open_runtime(&no_table).expect_err("refused again").to_string();
    assert!(e.contains("failed to start earlier"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
