//! `sublevel fit`. STUB.

/// Arguments of `sublevel fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {}

/// Runs `sublevel fit`.
pub fn run(_args: FitArgs) -> sublevel::Result<()> {
    Err(sublevel::Error::Numerical("`fit` not implemented yet".into()))
}
