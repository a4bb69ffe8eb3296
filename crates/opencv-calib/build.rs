//! Compiles the C++ shim (`crates/opencv-calib/src/shim.cpp`) against Debian's OpenCV 4 and links the three
//! modules it calls: core, imgproc and calib3d (their own dependencies come with them).
//!
//! pkg-config's `opencv4` gives the include paths and the library directories; of its
//! libraries (every module Debian builds) only those three are linked, so a program that uses
//! this crate loads no more of OpenCV than calibration needs.

/// The shim's source.
const SHIM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src/shim.cpp");

/// The OpenCV modules the shim calls, in link order (each before those it needs).
const MODULES: [&str; 3] = ["opencv_calib3d", "opencv_imgproc", "opencv_core"];

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={SHIM}");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");

    let opencv = pkg_config::Config::new()
        .atleast_version("4")
        .cargo_metadata(false)
        .probe("opencv4")
        .unwrap_or_else(|e| panic!("pkg-config opencv4: {e}; install libopencv-dev (scripts/setup.sh does)"));
    for module in MODULES {
        assert!(
            opencv.libs.iter().any(|lib| lib == module),
            "pkg-config opencv4 lists no {module} in {:?}",
            opencv.libs
        );
    }

    cc::Build::new()
        .cpp(true)
        .std("c++17")
        .flag("-O2")
        .includes(&opencv.include_paths)
        .file(SHIM)
        .compile("opencv_calib_shim");

    for dir in &opencv.link_paths {
        println!("cargo:rustc-link-search=native={}", dir.display());
    }
    for module in MODULES {
        println!("cargo:rustc-link-lib=dylib={module}");
    }
}
