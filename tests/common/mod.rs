//! What several test binaries share: the fast Cornell bake settings and the check that a
//! run of the `surfcache` binary succeeded.

use std::process::Output;

/// Small settings that keep a Cornell bake to about a second: no gathering pre-pass
/// (whose fixed 32-per-metre maps would take most of the time), a 10 % bound, 8 samples
/// per metre, two threads.
pub const CORNELL_FAST: [&str; 12] = [
    "--max-rel-error",
    "0.1",
    "--density",
    "8",
    "--gather",
    "0",
    "--min-samples",
    "64",
    "--max-samples",
    "4096",
    "--threads",
    "2",
];

/// The run exited 0; otherwise fails showing its status and stderr.
#[track_caller]
pub fn expect_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed: {:?}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}
