//! Compiles the native Embree driver (native/embree_driver.c) against
//! Embree 3's own headers when they are installed (Debian's libembree-dev,
//! which scripts/setup.sh installs), and links it with libembree3.
//!
//! Why C and a build script: the driver exists to show what a native Embree
//! application reaches, so it uses Embree's headers (its ray layouts and
//! inline `rtcInitIntersectContext`) rather than the Rust transcription the
//! core's binding carries. Where the headers are absent the bench still
//! builds; `native_embree` then reports the driver as not built and says why.

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=native/embree_driver.c");
    println!("cargo:rerun-if-env-changed=EMBREE_INCLUDE_DIR");
    println!("cargo:rustc-check-cfg=cfg(rendiff_native_embree)");
    let include = std::env::var_os("EMBREE_INCLUDE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/include"));
    let header = include.join("embree3/rtcore.h");
    println!("cargo:rerun-if-changed={}", header.display());
    // Package managers install headers with their release's mtime, older
    // than a build that ran before them (scripts/setup.sh runs after
    // .ci/run's clippy), so the header alone would not re-run this script;
    // the directory holding it is created at install time.
    println!(
        "cargo:rerun-if-changed={}",
        include.join("embree3").display()
    );
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let why = match build(&include, &header, &out) {
        Ok(()) => {
            println!("cargo:rustc-link-search=native={}", out.display());
            println!("cargo:rustc-link-lib=static=embree_driver");
            println!("cargo:rustc-link-lib=dylib=embree3");
            println!("cargo:rustc-cfg=rendiff_native_embree");
            String::new()
        }
        Err(why) => {
            println!("cargo:warning=native Embree driver not built: {why}");
            why
        }
    };
    // The reason travels into the binary, so the bench can say it.
    std::fs::write(out.join("native_embree_absent.txt"), why).expect("write OUT_DIR");
}

/// Compiles and archives the driver, or says why it could not.
fn build(include: &Path, header: &Path, out: &Path) -> Result<(), String> {
    if !header.exists() {
        return Err(format!(
            "{} absent (install libembree-dev, as scripts/setup.sh does)",
            header.display()
        ));
    }
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let obj = out.join("embree_driver.o");
    let status = Command::new(&cc)
        .args(["-O2", "-fPIC", "-std=c11", "-Wall", "-Wextra", "-c"])
        .arg("-I")
        .arg(include)
        .arg("native/embree_driver.c")
        .arg("-o")
        .arg(&obj)
        .status()
        .map_err(|e| format!("cannot run {cc}: {e}"))?;
    if !status.success() {
        return Err(format!("{cc} failed on native/embree_driver.c ({status})"));
    }
    let ar = std::env::var("AR").unwrap_or_else(|_| "ar".into());
    let lib = out.join("libembree_driver.a");
    let _ = std::fs::remove_file(&lib);
    let status = Command::new(&ar)
        .arg("crs")
        .arg(&lib)
        .arg(&obj)
        .status()
        .map_err(|e| format!("cannot run {ar}: {e}"))?;
    if !status.success() {
        return Err(format!("{ar} failed ({status})"));
    }
    Ok(())
}
