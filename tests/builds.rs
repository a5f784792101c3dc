//! One feature set for the three things users build: the CLI (`cargo build --release --bin
//! zoo`), the C library (`cargo build --release -p zoo-capi`) and the Python wheel (`zoo-python`,
//! built by maturin). Cargo compiles a dependency once per set of features, so a crate that the
//! three share with different features is compiled again for each (tract took 24 minutes on two
//! cores when the C library was built after the CLI). `zoo-runtime`'s Cargo.toml turns on the
//! features the CLI's graph turns on; this test asserts, with `cargo tree`, that every package
//! the C library's or the wheel's build has in common with the CLI's has the same features.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// `package version` to its feature sets (one for code, one for build scripts and proc macros
/// where they differ), in the build of `root` (normal and build dependencies).
fn features(root: &str) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["tree", "--offline", "-p", root, "-e", "normal,build", "-f", "{p}|{f}", "--prefix", "none"])
        .output()
        .expect("cannot run cargo tree");
    assert!(out.status.success(), "cargo tree -p {root} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let mut map = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Some((package, features)) =
            line.replace(" (*)", "").split_once('|').map(|(p, f)| (p.to_string(), f.to_string()))
        else {
            continue;
        };
        let name = package.split_whitespace().take(2).collect::<Vec<_>>().join(" ");
        let mut set: Vec<&str> = features.split(',').filter(|f| !f.is_empty()).collect();
        set.sort_unstable();
        map.entry(name).or_insert_with(BTreeSet::new).insert(set.join(","));
    }
    map
}

#[test]
fn the_c_library_and_the_wheel_build_with_the_clis_features() {
    let cli = features("zoo-cli");
    for root in ["zoo-capi", "zoo-python"] {
        let other = features(root);
        let differ: Vec<String> = other
            .iter()
            .filter_map(|(p, f)| {
                let c = cli.get(p)?;
                (c != f).then(|| format!("{p}: the CLI's build has {c:?}, {root}'s {f:?}"))
            })
            .collect();
        assert!(
            differ.is_empty(),
            "{root} would compile these shared crates again after the CLI's build (pin the CLI's features in \
             runtime/runtime/Cargo.toml):\n{}",
            differ.join("\n")
        );
        assert!(other.keys().any(|p| p.starts_with("tract-core ")), "{root}'s build has tract");
    }
}
