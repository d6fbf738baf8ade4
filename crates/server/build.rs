//! Compiles `proto/sublevel/v1/sublevel.proto` and the message files it imports with protox (pure Rust, no system `protoc`) and
//! tonic-prost-build, and writes the encoded descriptor set for server reflection to
//! `$OUT_DIR/sublevel_descriptor.bin`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    use protox::prost::Message;
    let proto = "../../proto/sublevel/v1/sublevel.proto";
    println!("cargo:rerun-if-changed=../../proto");
    let fds = protox::compile([proto], ["../../proto"])?;
    let out_dir = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out_dir.join("sublevel_descriptor.bin"), fds.encode_to_vec())?;
    tonic_prost_build::configure().build_server(true).build_client(true).compile_fds(fds)?;
    Ok(())
}
