//! The `mousepose` binary: everything happens in the library's [`mousepose::cli::main`].

fn main() -> std::process::ExitCode {
    mousepose::cli::main()
}
