//! `sublevel bench`. STUB.

/// Arguments of `sublevel bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {}

/// Runs `sublevel bench`.
pub fn run(_args: BenchArgs) -> sublevel::Result<()> {
    Err(sublevel::Error::Numerical("`bench` not implemented yet".into()))
}
