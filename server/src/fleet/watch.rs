//! The GameServer watch (`Sdk::watch_gameserver`): the sidecar streams the server's GameServer at each change
//! (an allocation's annotations and counter raise among them). A stream that ends or fails (a sidecar that
//! restarts) is reopened with backoff and reported; the watch never ends the adapter.

use std::collections::HashMap;

use agones::{GameServer, Sdk};
use futures_util::stream::{BoxStream, StreamExt};

use super::sidecar::{describe, FIRST_BACKOFF, MAX_BACKOFF};

/// The open watch, if any, and how often in a row it failed.
pub(super) struct GameServerWatch {
    sdk: Sdk,
    /// The SDK's stream, its errors as text (the gRPC status, which names what failed).
    stream: Option<BoxStream<'static, Result<GameServer, String>>>,
    failures: u32,
}

impl GameServerWatch {
    /// Opens the watch (a failure is reported and retried by [`GameServerWatch::next`]).
    pub async fn open(sdk: &Sdk) -> Self {
        let mut watch = GameServerWatch { sdk: sdk.clone(), stream: None, failures: 0 };
        watch.reopen().await;
        watch
    }

    /// The annotations of the next GameServer the sidecar sends; waits, reopening the stream as it must,
    /// until one comes. Dropping the future loses no update (the stream keeps its place).
    pub async fn next(&mut self) -> HashMap<String, String> {
        loop {
            if let Some(stream) = &mut self.stream {
                match stream.next().await {
                    Some(Ok(gameserver)) => {
                        self.failures = 0;
                        return gameserver.object_meta.map(|meta| meta.annotations).unwrap_or_default();
                    }
                    None => tracing::warn!("the Agones GameServer watch ended; reopening it"),
                    Some(Err(status)) => tracing::warn!(status, "the Agones GameServer watch failed; reopening it"),
                }
                self.stream = None;
                self.failures += 1;
            }
            let backoff = FIRST_BACKOFF.saturating_mul(1 << self.failures.min(5)).min(MAX_BACKOFF);
            tokio::time::sleep(backoff).await;
            self.reopen().await;
        }
    }

    async fn reopen(&mut self) {
        match self.sdk.clone().watch_gameserver().await {
            Ok(stream) => self.stream = Some(stream.map(|item| item.map_err(|status| status.to_string())).boxed()),
            Err(error) => {
                self.failures += 1;
                if self.failures.is_power_of_two() {
                    let failures = self.failures;
                    tracing::warn!(failures, error = %describe(&error), "cannot watch the Agones GameServer; retrying");
                }
            }
        }
    }
}
