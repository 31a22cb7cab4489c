//! kinloop-server (work in progress).
