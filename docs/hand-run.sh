# A session by hand, from the top of a checkout. The README quotes this file; tests/slow/hand_run.rs runs its
# `cargo run` lines as written (with a free port and the printed fingerprint), so they cannot drift.

# 1. In one terminal, the server (Ctrl-C stops it). It prints the address it listens on and the SHA-256
#    fingerprint of its certificate, which clients pin.
cargo run --release -p kinloop-server -- --scene fourbar-crank-rocker --listen 127.0.0.1:4433

# 2. In another terminal, paste that fingerprint, then run a client for 5 s: a simulated hand tours the
#    scene's first operational point on a simulated device. At exit it prints its timing and how closely
#    the device tracked the linkage (add --json for one JSON object).
FINGERPRINT=paste-the-fingerprint-here
cargo run --release -p kinloop-client -- --server 127.0.0.1:4433 --fingerprint "$FINGERPRINT" --duration 5

# 3. The same with 50 ms (± 5 ms) added to everything the client sends, as a slow network would.
cargo run --release -p kinloop-client -- --server 127.0.0.1:4433 --fingerprint "$FINGERPRINT" --duration 5 --delay 50ms --jitter 5ms
