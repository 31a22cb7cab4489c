//! What every exchange with the Agones SDK sidecar shares: the backoff between retries, and the SDK's errors
//! as text.

use std::time::Duration;

/// The first wait between retries; it doubles up to [`MAX_BACKOFF`].
pub(super) const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// The longest wait between retries.
pub(super) const MAX_BACKOFF: Duration = Duration::from_secs(2);

/// The SDK's error with its causes (its own text for a failed call is only "rpc failure").
pub(super) fn describe(error: &agones::errors::Error) -> String {
    let mut text = error.to_string();
    let mut source = std::error::Error::source(error);
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}
