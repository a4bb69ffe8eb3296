//! Generates the OpenNI2 C API bindings from the installed headers and links `libOpenNI2`.
//!
//! The headers come from pkg-config's `libopenni2` when it is there (Debian ships a `.pc`),
//! otherwise from `/usr/include/openni2`. `OniCAPI.h` only parses as C++ (it names
//! `_OniDevice*` without `struct`), so clang is told `-x c++ -std=c++11`; every OpenNI function
//! is `extern "C"`, so the generated declarations link against the C symbols.

use std::env;
use std::path::PathBuf;

const FALLBACK_INCLUDE: &str = "/usr/include/openni2";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");

    let include_dirs = match pkg_config::Config::new().atleast_version("2.2").probe("libopenni2") {
        // pkg-config printed the link flags (`-lOpenNI2`) for cargo.
        Ok(lib) if !lib.include_paths.is_empty() => lib.include_paths,
        Ok(_) => vec![PathBuf::from(FALLBACK_INCLUDE)],
        Err(error) => {
            println!("cargo:warning=pkg-config libopenni2: {error}; using {FALLBACK_INCLUDE}");
            println!("cargo:rustc-link-lib=dylib=OpenNI2");
            vec![PathBuf::from(FALLBACK_INCLUDE)]
        }
    };

    let header = include_dirs
        .iter()
        .map(|dir| dir.join("OniCAPI.h"))
        .find(|path| path.is_file())
        .unwrap_or_else(|| {
            panic!("OniCAPI.h not found in {include_dirs:?}: install libopenni2-dev (scripts/setup.sh does)")
        });
    println!("cargo:rerun-if-changed={}", header.display());

    let mut builder = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .clang_args(["-x", "c++", "-std=c++11"])
        .allowlist_function("oni.*")
        .allowlist_type("Oni.*|_Oni.*")
        .allowlist_var("ONI_.*")
        // The anonymous enums of OniCProperties.h (property ids) and OniCEnums.h (timeouts)
        // become constants; the named ones (OniStatus, OniPixelFormat...) plain integer
        // aliases with constants too, since the driver may hand back values outside them.
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .derive_default(true)
        .derive_debug(true)
        .layout_tests(true)
        .generate_comments(false)
        .parse_callbacks(Box::new(bindgen::CargoCallbacks::new()));
    for dir in &include_dirs {
        builder = builder.clang_arg(format!("-I{}", dir.display()));
    }
    let bindings = builder
        .generate()
        .expect("bindgen could not generate the OpenNI2 bindings");

    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("bindings.rs");
    bindings.write_to_file(&out).expect("writing the OpenNI2 bindings");
}
