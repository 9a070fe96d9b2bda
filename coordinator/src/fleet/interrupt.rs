//! Interrupting a render: the first SIGINT (Ctrl-C) or SIGTERM asks the render to stop, keep what is finished in
//! the partial file and say how to resume ([`crate::farm::FarmError::Interrupted`]); a second one ends the
//! process at once.

use tokio::sync::watch;

/// The signal that interrupted a render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interrupt {
    /// SIGINT (Ctrl-C).
    Int,
    /// SIGTERM.
    Term,
}

impl Interrupt {
    /// The signal's name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Int => "SIGINT",
            Self::Term => "SIGTERM",
        }
    }

    /// The exit status of a process that a signal stopped: 128 + the signal's number (130 for SIGINT, 143 for
    /// SIGTERM), as shells report it.
    pub fn exit_code(self) -> i32 {
        match self {
            Self::Int => 130,
            Self::Term => 143,
        }
    }
}

impl std::fmt::Display for Interrupt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What a render watches for an interruption: `None` until the first signal.
pub type Interrupts = watch::Receiver<Option<Interrupt>>;

/// Watches SIGINT and SIGTERM from now on (call it inside the runtime): the first sets the value the returned
/// receiver sees; a second ends the process at once with that signal's exit status, without the partial file.
/// Where the signals cannot be watched, says so in the log and returns a receiver that never changes.
pub fn watch_signals() -> Interrupts {
    let (tx, rx) = watch::channel(None);
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match (signal(SignalKind::interrupt()), signal(SignalKind::terminate())) {
            (Ok(mut int), Ok(mut term)) => {
                tokio::spawn(async move {
                    loop {
                        let got = tokio::select! {
                            Some(()) = int.recv() => Interrupt::Int,
                            Some(()) = term.recv() => Interrupt::Term,
                            else => return,
                        };
                        if tx.borrow().is_some() {
                            eprintln!("\n{got} again: stopping at once, without saving the finished strips");
                            std::process::exit(got.exit_code());
                        }
                        eprintln!(
                            "\n{got}: stopping the workers and saving the finished strips (send it again to stop at \
                             once)"
                        );
                        let _ = tx.send(Some(got));
                    }
                });
            }
            (Err(e), _) | (_, Err(e)) => tracing::warn!("cannot watch SIGINT and SIGTERM: {e}"),
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tx;
        tracing::warn!("interrupting a render keeps no partial file on this platform");
    }
    rx
}

/// Resolves with the first interruption seen by `rx`, or never when there is none to watch.
pub async fn interrupted(rx: Option<&mut Interrupts>) -> Interrupt {
    if let Some(rx) = rx
        && let Ok(v) = rx.wait_for(Option::is_some).await
        && let Some(sig) = *v
    {
        return sig;
    }
    std::future::pending().await
}
