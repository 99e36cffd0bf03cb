//! The `surfcache` binary: see `surfcache --help` and docs/cli.md.

fn main() -> std::process::ExitCode {
    surfcache_cli::main()
}
