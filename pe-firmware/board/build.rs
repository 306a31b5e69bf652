//! Picks the memory map (board or QEMU), appends the schedule region's section, and links a
//! schedule image into it when `PE_SCHEDULE_IMAGE` names one.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let root =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("../..");
    let memory = if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        root.join("memory-qemu.x")
    } else {
        root.join("memory.x")
    };
    let mut script =
        fs::read_to_string(&memory).unwrap_or_else(|e| panic!("reading {}: {e}", memory.display()));
    script.push('\n');
    script.push_str(&fs::read_to_string("schedule.x").expect("reading schedule.x"));
    fs::write(out.join("memory.x"), script).expect("writing memory.x");

    // The schedule image linked into the IMAGE region: u32 length (LE), then the image.
    let mut blob = Vec::new();
    if let Some(p) = env::var_os("PE_SCHEDULE_IMAGE").filter(|p| !p.is_empty()) {
        let p = PathBuf::from(p);
        let image =
            fs::read(&p).unwrap_or_else(|e| panic!("PE_SCHEDULE_IMAGE={}: {e}", p.display()));
        blob.extend_from_slice(&(image.len() as u32).to_le_bytes());
        blob.extend_from_slice(&image);
        println!("cargo:rerun-if-changed={}", p.display());
    }
    fs::write(out.join("schedule.bin"), blob).expect("writing schedule.bin");

    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
    println!("cargo:rerun-if-env-changed=PE_SCHEDULE_IMAGE");
    println!("cargo:rerun-if-changed=schedule.x");
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed=build.rs");
}
