//! The fake sidecar's server stubs, generated from the wire contract in `proto/` (the messages and methods
//! kinloop's Agones adapter uses, with Agones' package names, method names and field numbers).

fn main() {
    tonic_build::configure()
        .build_client(false)
        .compile_protos(&["proto/sdk.proto", "proto/beta.proto"], &["proto"])
        .expect("the fake sidecar's protocol compiles (protoc must be installed)");
}
