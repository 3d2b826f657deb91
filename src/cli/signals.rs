//! SIGINT and SIGTERM: a run stopped by either deletes the temporaries of the outputs it had not
//! yet renamed into place, then exits with 128 + the signal's number, as a shell reports it
//! (issue 33: `plot` and `lut` left `.workbench-*.tmp` files). The previous outputs stay as they
//! were, since nothing was renamed over them (src/formats/output.rs).

/// Block both signals in this thread before any other starts — every later thread inherits the
/// mask — and wait for them on a thread of its own, where the clean-up may take locks (a signal
/// handler could not).
#[cfg(unix)]
pub(crate) fn clean_up_on_signals() {
    // SAFETY: plain libc calls on a zeroed, then initialised, signal set owned by this function
    // (moved into the waiting thread); no memory is shared with a handler.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            return;
        }
        std::thread::spawn(move || {
            let mut sig: libc::c_int = 0;
            if libc::sigwait(&set, &mut sig) == 0 {
                workbench::formats::output::exit_discarding_temporaries(128 + sig);
            }
        });
    }
}

/// Elsewhere the default handling stays (a stopped run may leave hidden temporaries).
#[cfg(not(unix))]
pub(crate) fn clean_up_on_signals() {}
