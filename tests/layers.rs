//! The layers of the workspace (README, "The repository"): core (`core/`) < offline
//! (`offline/`) < runtime (`runtime/`) < apps (`apps/`, and these workspace tests). A crate
//! depends (normal, dev or build dependency) only on crates of its own layer or lower ones, and
//! the small motion core (`zoo-motion`) on no crate of the workspace. Read from `cargo metadata`.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// The layer of a crate from its folder under the workspace root, lowest first.
fn layer(dir: &Path, root: &Path) -> usize {
    let top = dir
        .strip_prefix(root)
        .ok()
        .and_then(|p| p.components().next())
        .map(|c| c.as_os_str().to_string_lossy().into_owned());
    match top.as_deref() {
        Some("core") => 0,
        Some("offline") => 1,
        Some("runtime") => 2,
        Some("apps" | "tests") => 3,
        other => panic!("{}: a crate outside the four layers' folders ({other:?})", dir.display()),
    }
}

#[test]
fn every_crate_depends_only_on_its_own_layer_or_lower_ones() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["metadata", "--format-version", "1", "--no-deps", "--offline"])
        .output()
        .expect("cannot run cargo metadata");
    assert!(out.status.success(), "cargo metadata failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("cargo metadata's JSON");
    let root = Path::new(meta["workspace_root"].as_str().expect("workspace_root"));
    let packages = meta["packages"].as_array().expect("packages");
    // Every workspace crate by name: its folder and layer.
    let crates: BTreeMap<&str, usize> = packages
        .iter()
        .map(|p| {
            let dir = Path::new(p["manifest_path"].as_str().expect("manifest_path")).parent().expect("a folder");
            (p["name"].as_str().expect("name"), layer(dir, root))
        })
        .collect();
    const NAMES: [&str; 4] = ["core", "offline", "runtime", "apps"];
    let mut wrong = Vec::new();
    for p in packages {
        let name = p["name"].as_str().expect("name");
        let own = crates[name];
        for d in p["dependencies"].as_array().expect("dependencies") {
            let dep = d["name"].as_str().expect("dependency name");
            let Some(&theirs) = crates.get(dep) else { continue };
            let kind = d["kind"].as_str().unwrap_or("normal");
            if theirs > own {
                wrong.push(format!("{name} ({}) has a {kind} dependency on {dep} ({})", NAMES[own], NAMES[theirs]));
            }
            if name == "zoo-motion" {
                wrong.push(format!("zoo-motion, the small motion core, has a {kind} dependency on {dep}"));
            }
        }
    }
    assert!(crates.contains_key("zoo-motion") && crates.len() > 10, "the workspace's crates: {crates:?}");
    assert!(
        wrong.is_empty(),
        "dependencies against the layers (core < offline < runtime < apps):\n{}",
        wrong.join("\n")
    );
}
