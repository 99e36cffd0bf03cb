//! The surfcache command-line tool.

/// Runs the command line; returns the process exit code.
pub fn main() -> std::process::ExitCode {
    std::process::ExitCode::SUCCESS
}
