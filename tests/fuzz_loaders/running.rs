//! Running a property: the proptest runner, what the loaders returned, seeds and messages.

use crate::panics::{serial, take_panics};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What the loaders returned over a run.
#[derive(Default)]
pub(crate) struct Stats {
    ok: usize,
    err: usize,
    /// Error messages with the file name and digits blanked, and how often each came.
    causes: BTreeMap<String, usize>,
    /// The slowest case: seconds and outcome.
    slowest: (f64, String),
}

impl Stats {
    fn record(&mut self, outcome: &Result<(), String>, file: &Path, seconds: f64) {
        if seconds > self.slowest.0 {
            let what = match outcome {
                Ok(()) => "loaded".to_string(),
                Err(e) => e.clone(),
            };
            self.slowest = (seconds, what);
        }
        match outcome {
            Ok(()) => self.ok += 1,
            Err(message) => {
                self.err += 1;
                let mut cause = message.replace(&file.display().to_string(), "<file>");
                cause = cause
                    .chars()
                    .map(|c| if c.is_ascii_digit() { '#' } else { c })
                    .collect();
                while cause.contains("##") {
                    cause = cause.replace("##", "#");
                }
                let cause: String = cause.chars().take(110).collect();
                *self.causes.entry(cause).or_default() += 1;
            }
        }
    }

    fn print(&self, name: &str, cases: u32, seconds: f64, top: usize) {
        println!(
            "{name}: {cases} cases in {seconds:.1} s: {} loaded, {} rejected, {} distinct causes",
            self.ok,
            self.err,
            self.causes.len()
        );
        println!(
            "  slowest case {:.3} s: {}",
            self.slowest.0,
            self.slowest.1.chars().take(200).collect::<String>()
        );
        let mut causes: Vec<_> = self.causes.iter().collect();
        causes.sort_by(|a, b| b.1.cmp(a.1));
        for (cause, n) in causes.into_iter().take(top) {
            println!("  {n:>6}  {cause}");
        }
    }
}

/// The seed: `SURFCACHE_FUZZ_SEED`, else `default` (None: from the clock).
pub(crate) fn seed(default: Option<u64>) -> u64 {
    match std::env::var("SURFCACHE_FUZZ_SEED") {
        Ok(s) => s
            .trim()
            .parse()
            .expect("SURFCACHE_FUZZ_SEED must be an unsigned integer"),
        Err(_) => default.unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.as_nanos() as u64)
        }),
    }
}

/// Runs `cases` cases of `property` on inputs from `strategy`. `property` loads the file it
/// writes and returns (the file, the loader's outcome as `Ok(())` or the error's message), or
/// a violated property as `Err`. Panics with the minimal failing input and `rerun`, the
/// command that runs the failing cases again.
pub(crate) fn fuzz<S: Strategy>(
    name: &str,
    cases: u32,
    seed: u64,
    rerun: &str,
    strategy: S,
    property: impl Fn(&S::Value) -> Result<(PathBuf, Result<(), String>), String>,
) -> Stats
where
    S::Value: Debug,
{
    let _serial = serial();
    let stats = RefCell::new(Stats::default());
    let config = Config {
        cases,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(seed),
        max_shrink_iters: 4096,
        ..Config::default()
    };
    let started = Instant::now();
    let mut runner = TestRunner::new(config);
    take_panics();
    let result = runner.run(&strategy, |input| {
        take_panics();
        let case_started = Instant::now();
        let outcome = property(&input);
        let seconds = case_started.elapsed().as_secs_f64();
        let panics = take_panics();
        if !panics.is_empty() {
            return Err(TestCaseError::fail(format!(
                "the loader panicked: {}",
                panics.join("; ")
            )));
        }
        let (file, outcome) = outcome.map_err(TestCaseError::fail)?;
        stats.borrow_mut().record(&outcome, &file, seconds);
        Ok(())
    });
    if let Err(e) = result {
        panic!("{name} (case seed {seed}; again: {rerun}): {e}");
    }
    let stats = stats.into_inner();
    stats.print(name, cases, started.elapsed().as_secs_f64(), 8);
    stats
}

/// An `IoError` message, which must be one printable line.
pub(crate) fn message(e: &surfcache::io::IoError) -> Result<String, String> {
    let m = e.to_string();
    if m.is_empty() || !printable(&m) {
        return Err(format!("error message is not one printable line: {m:?}"));
    }
    Ok(m)
}

/// Whether a message holds no control characters (C0, DEL, C1: line breaks, terminal
/// escapes) and none of the invisible format characters that reorder or hide text.
pub(crate) fn printable(m: &str) -> bool {
    !m.chars().any(|c| {
        c.is_control()
            || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2028}'
                | '\u{2029}' | '\u{2066}'..='\u{2069}' | '\u{feff}' | '\u{61c}')
    })
}
