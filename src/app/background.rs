//! What the inspector's background threads (the worker, the decoder, the tasks) share: they
//! yield the cores to the window.

/// Lowers the calling thread's scheduling priority (Linux: its nice value to 10) so that the
/// window's thread, and the renderer's, get the cores first: on two cores a tracker running
/// flat out otherwise starves the window (12 fps measured with two learning trackers). The
/// trackers lose only what the window uses. Elsewhere it does nothing.
pub(super) fn yield_to_window() {
    #[cfg(target_os = "linux")]
    // SAFETY: gettid and setpriority take and return plain integers; on Linux a thread id is a
    // valid PRIO_PROCESS target and the call changes that thread alone. A failure (as from a
    // sandbox that forbids it) leaves the priority as it was, which is harmless.
    unsafe {
        let tid = libc::gettid();
        libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, 10);
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    #[test]
    fn background_threads_yield_to_the_window() {
        // SAFETY: reads the calling thread's nice value; plain integers in and out.
        let nice =
            || unsafe { libc::getpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t) };
        let before = nice();
        let niceness = std::thread::spawn(move || {
            super::yield_to_window();
            nice()
        })
        .join()
        .unwrap();
        // 10, or more when the test itself runs at a lower priority.
        assert!(niceness >= 10, "nice {niceness}");
        assert_eq!(nice(), before, "the calling thread keeps its priority");
    }
}
