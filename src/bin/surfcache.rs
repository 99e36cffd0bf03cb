//! The `surfcache` binary: see `surfcache --help` and CONTRACT.md.

fn main() -> std::process::ExitCode {
    surfcache_cli::main()
}
