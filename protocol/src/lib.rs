//! kinloop-protocol (work in progress).
