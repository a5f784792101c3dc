//! The C examples of `runtime/capi/examples` built and run by `tests/capi.rs` and
//! `tests/capi_tasks.rs` (a module of both, not a test target of its own).

use std::path::{Path, PathBuf};
use std::process::Command;
use zoo_tests::capi::{capi_dir, compile_example, static_lib};

/// Compiles `examples/NAME.c` as C++17 with the system C++ compiler (`CXX`, else `c++`; every
/// warning an error) against the static library into `dir/NAME-cpp`.
fn compile_example_cpp(name: &str, dir: &Path) -> PathBuf {
    let exe = dir.join(format!("{name}-cpp"));
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    let capi = capi_dir();
    let out = Command::new(&cxx)
        .args(["-std=c++17", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(capi.join("include"))
        .args(["-x", "c++"])
        .arg(capi.join(format!("examples/{name}.c")))
        .args(["-x", "none"])
        .arg(static_lib())
        .args(["-lm", "-lpthread", "-ldl", "-lrt", "-lgcc_s", "-lc", "-o"])
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("cannot run the C++ compiler `{cxx}` ({e}); install g++ or set CXX"));
    assert!(
        out.status.success(),
        "the C example {name}.c does not compile as C++17:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Runs `exe` with `args`; its standard output.
fn run(exe: &Path, args: &[String]) -> String {
    let run = Command::new(exe).args(args).output().unwrap();
    assert!(run.status.success(), "{} failed:\n{}", exe.display(), String::from_utf8_lossy(&run.stderr));
    String::from_utf8(run.stdout).unwrap()
}

/// Compiles `examples/NAME.c` as C99 (`zoo_tests::capi::compile_example`) and as C++17 into
/// `dir`, runs both with `args`, checks that they print the same, and returns what they print.
pub fn run_as_c99_and_cpp17(name: &str, dir: &Path, args: &[String]) -> String {
    let c = run(&compile_example(name, dir), args);
    let cpp = run(&compile_example_cpp(name, dir), args);
    assert!(cpp == c, "examples/{name}.c built as C++17 prints other numbers than built as C99");
    c
}
