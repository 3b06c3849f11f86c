//! Placeholder until the identification tool lands.
use std::path::PathBuf;

/// Arguments of `hter identify`.
#[derive(clap::Args, Debug, Clone)]
pub struct IdentifyArgs {
    /// CSV log.
    #[arg(long)]
    pub input: PathBuf,
}

/// `hter identify`.
pub fn run(args: &IdentifyArgs) -> anyhow::Result<()> {
    anyhow::bail!("cannot read '{}': identify is not available yet", args.input.display())
}
