//! kinloop-client (work in progress).
