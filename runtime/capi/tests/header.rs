//! `include/zoo.h` is what cbindgen generates from `src` with `cbindgen.toml`, and declares the
//! ABI version the library reports.

use std::path::Path;

#[test]
fn header_is_up_to_date() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    // cbindgen follows lib.rs's `mod` declarations into the task modules.
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let header = dir.join("include/zoo.h");
    if std::env::var_os("ZOO_BLESS_HEADER").is_some() {
        std::fs::write(&header, &generated).unwrap();
    }
    let committed = std::fs::read(&header).unwrap_or_default();
    assert!(
        committed == generated,
        "runtime/capi/include/zoo.h is not what cbindgen generates from runtime/capi/src; regenerate it with \
         `ZOO_BLESS_HEADER=1 cargo test -p zoo-capi --test header` and commit it"
    );
}

#[test]
fn the_header_declares_the_abi_version_of_the_library() {
    let header = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("include/zoo.h")).unwrap();
    let define = format!("#define ZOO_ABI_VERSION {}", zoo_capi::ZOO_ABI_VERSION);
    assert!(header.contains(&define), "zoo.h should contain `{define}`");
    assert!(
        header.contains(&format!("C ABI version {}.", zoo_capi::zoo_abi_version())),
        "the banner names the version"
    );
}
