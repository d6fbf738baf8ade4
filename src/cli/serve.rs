//! `sublevel serve`. STUB.

/// Arguments of `sublevel serve`.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {}

/// Runs `sublevel serve`.
pub fn run(_args: ServeArgs) -> sublevel::Result<()> {
    Err(sublevel::Error::Numerical("`serve` not implemented yet".into()))
}
