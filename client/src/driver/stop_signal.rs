//! The signals that ask a kinloop process to stop: SIGINT (Ctrl-C) and, on Unix, SIGTERM (what `kill`, systemd
//! and container runtimes send). Once this is awaited the process no longer dies on them, so whoever awaits it
//! owns the clean stop: for a client, the haptic loop's own exit, which commands zero force, disables forces and
//! releases the device (its lease's `Drop`) before the process ends.

/// Resolves when SIGINT or SIGTERM arrives. Registers the handlers on first poll; must run inside a tokio
/// runtime with signals enabled. When a handler cannot be installed, that signal is not awaited (the other
/// still is) and the failure is logged once.
pub async fn stop_requested() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let terminate = async {
            match signal(SignalKind::terminate()) {
                Ok(mut stream) => {
                    stream.recv().await;
                }
                Err(e) => {
                    tracing::warn!("cannot handle SIGTERM ({e}); only Ctrl-C stops this process cleanly");
                    std::future::pending::<()>().await
                }
            }
        };
        tokio::select! {
            _ = interrupt() => {}
            _ = terminate => {}
        }
    }
    #[cfg(not(unix))]
    interrupt().await
}

/// Resolves on Ctrl-C; never when its handler cannot be installed (said once).
async fn interrupt() {
    if let Err(e) = tokio::signal::ctrl_c().await {
        tracing::warn!("cannot handle Ctrl-C ({e})");
        std::future::pending::<()>().await
    }
}
