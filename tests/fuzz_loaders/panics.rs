//! Panics and serial execution: a process-wide panic record, one fuzz test at a time.

use std::sync::{Mutex, MutexGuard, Once, PoisonError};

/// Held by every fuzz test: the panic record below is process-wide.
static SERIAL: Mutex<()> = Mutex::new(());
/// Every panic since the last [`take_panics`], from any thread ("message at file:line").
static PANICS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Panics that are allowed although a loader catches them with `no_panic`: (source file
/// suffix, message substring), each with the reason it cannot be validated beforehand.
const ALLOWED_PANICS: &[(&str, &str)] = &[];

/// Installs the recording panic hook (once) and takes the serial lock.
pub(crate) fn serial() -> MutexGuard<'static, ()> {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let message = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "(no message)".into());
            let location = info
                .location()
                .map(|l| format!("{}:{}", l.file(), l.line()))
                .unwrap_or_default();
            PANICS
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(format!("'{message}' at {location}"));
            previous(info);
        }));
    });
    SERIAL.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The panics recorded since the last call, less the documented [`ALLOWED_PANICS`].
pub(crate) fn take_panics() -> Vec<String> {
    let mut all = std::mem::take(&mut *PANICS.lock().unwrap_or_else(PoisonError::into_inner));
    all.retain(|p| {
        !ALLOWED_PANICS.iter().any(|(file, msg)| {
            p.contains(msg) && p.rsplit(" at ").next().is_some_and(|l| l.contains(file))
        })
    });
    all
}
