//! How kinloop's programs run and tell a person what went wrong: one line, each cause said once.
//!
//! Errors here and in the crates below usually say their cause in their own message *and* return it as
//! their `source()`: "cannot connect to 127.0.0.1:4433: the server refused: …", whose source says "the
//! server refused: …" again. Printing every link of the chain (anyhow's `{:#}`, or its `Caused by:` list)
//! then repeats the cause; printing only the first link loses what a context wrapped. [`one_line`] walks the
//! chain and adds a cause only when the line does not say it yet; [`run_program`] is how `kinloop`,
//! `kinloop-server` and `kinloop-client` run their bodies and end.
//!
//! A reader that stops reading (`kinloop inspect … | head`) closes the program's stdout. Like `cat` or
//! `ls`, a kinloop program then ends quietly with success: the output was not wanted any more, which is no
//! error. `println!` panics on a closed stdout ("failed printing to stdout: Broken pipe"), so the panic hook
//! turns exactly that panic into a quiet exit, and an error caused by a broken pipe is not reported either.

use std::error::Error;
use std::ffi::OsStr;
use std::io::IsTerminal;
use std::process::ExitCode;

/// Runs a program's `body` as kinloop's programs run: logs go to stderr, filtered by `RUST_LOG` or else
/// `default_filter` (a process that already has a subscriber, such as a test running the program in a
/// child, keeps its own), coloured only as [`log_colour`] says; a failure prints `error: ` and
/// [`one_line`] on stderr and ends with failure.
pub fn run_program<E>(default_filter: &str, body: impl FnOnce() -> Result<(), E>) -> ExitCode
where
    E: Into<Box<dyn Error + Send + Sync>>,
{
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_filter));
    let colour = log_colour(std::io::stderr().is_terminal(), std::env::var_os("NO_COLOR").as_deref());
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(colour).try_init();
    end_quietly_when_stdout_closes();
    match body().map_err(Into::into) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) if is_closed_stdout(&*error) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {}", one_line(&*error));
            ExitCode::FAILURE
        }
    }
}

/// Installs a panic hook that ends the process with success, printing nothing, when the panic is
/// `println!`'s on a closed stdout; every other panic goes to the hook that was there before.
fn end_quietly_when_stdout_closes() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message =
            payload.downcast_ref::<String>().map(String::as_str).or_else(|| payload.downcast_ref::<&str>().copied());
        if message.is_some_and(is_closed_stdout_panic) {
            std::process::exit(0);
        }
        previous(info);
    }));
}

/// Whether a panic message is the standard library's for a write to a stdout whose reader is gone.
pub fn is_closed_stdout_panic(message: &str) -> bool {
    message.starts_with("failed printing to stdout") && message.contains("Broken pipe")
}

/// Whether `error` or one of its causes is a broken pipe (a write to a stdout whose reader is gone).
pub fn is_closed_stdout(error: &(dyn Error + 'static)) -> bool {
    let mut cause = Some(error);
    while let Some(e) = cause {
        if e.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe) {
            return true;
        }
        cause = e.source();
    }
    false
}

/// Whether logs are coloured: only on a terminal (a file or a pipe gets plain text, no escape codes), and
/// never when `NO_COLOR` is set to anything but the empty string (<https://no-color.org>).
pub fn log_colour(stderr_is_terminal: bool, no_color: Option<&OsStr>) -> bool {
    stderr_is_terminal && no_color.is_none_or(OsStr::is_empty)
}

/// `error` and its causes on one line, joined by `": "`, leaving out every cause the line already says.
pub fn one_line(error: &(dyn Error + 'static)) -> String {
    let mut line = error.to_string();
    let mut cause = error.source();
    while let Some(e) = cause {
        let said = e.to_string();
        if !said.is_empty() && !line.contains(&said) {
            line.push_str(": ");
            line.push_str(&said);
        }
        cause = e.source();
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("the server refused: no such point")]
    struct Refusal;

    /// Says its source in its message and returns it as its source, as `#[error("..{0}")] X(#[from] E)` does.
    #[derive(Debug, thiserror::Error)]
    #[error("cannot connect to 127.0.0.1:4433: {0}")]
    struct Connect(#[from] Refusal);

    /// Says nothing of its source.
    #[derive(Debug, thiserror::Error)]
    #[error("the client could not start")]
    struct Context(#[source] Connect);

    #[test]
    fn a_cause_the_message_already_says_is_not_repeated() {
        assert_eq!(one_line(&Connect(Refusal)), "cannot connect to 127.0.0.1:4433: the server refused: no such point");
    }

    #[test]
    fn a_context_keeps_the_causes_it_does_not_say_each_once() {
        assert_eq!(
            one_line(&Context(Connect(Refusal))),
            "the client could not start: cannot connect to 127.0.0.1:4433: the server refused: no such point"
        );
    }

    #[test]
    fn logs_are_coloured_only_on_a_terminal_without_no_color() {
        assert!(log_colour(true, None));
        assert!(log_colour(true, Some(OsStr::new(""))), "an empty NO_COLOR does not count");
        assert!(!log_colour(true, Some(OsStr::new("1"))));
        assert!(!log_colour(false, None));
        assert!(!log_colour(false, Some(OsStr::new("1"))));
    }

    #[test]
    fn only_a_closed_stdout_is_recognised_as_one() {
        assert!(is_closed_stdout_panic("failed printing to stdout: Broken pipe (os error 32)"));
        assert!(!is_closed_stdout_panic("failed printing to stdout: No space left on device (os error 28)"));
        assert!(!is_closed_stdout_panic("index out of bounds: the len is 3 but the index is 3"));
        let pipe = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        assert!(!is_closed_stdout(&Context(Connect(Refusal))));
        assert!(is_closed_stdout(&pipe));
        #[derive(Debug, thiserror::Error)]
        #[error("cannot write the report")]
        struct Writing(#[source] std::io::Error);
        assert!(is_closed_stdout(&Writing(std::io::Error::from(std::io::ErrorKind::BrokenPipe))));
        assert!(!is_closed_stdout(&Writing(std::io::Error::from(std::io::ErrorKind::NotFound))));
    }

    #[test]
    fn an_error_without_a_source_is_its_message() {
        assert_eq!(one_line(&Refusal), "the server refused: no such point");
    }
}
