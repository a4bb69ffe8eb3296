//! The `mousepose` binary: everything happens in the library's [`mousepose::app::main`].

fn main() -> std::process::ExitCode {
    mousepose::app::main()
}
