//! `zoo train MODEL`: train a model of the zoo. The subcommands are the table of models
//! (`zoo_models::MODELS`): each model's options and training are its crate's entry
//! (`zoo_nn::ZooModel`); the options every trainer takes are `zoo_nn::train_args`.

use clap::{ArgMatches, FromArgMatches, Subcommand};

/// `zoo train MODEL ...`: the model's kind and its parsed options.
pub struct TrainCommand {
    kind: String,
    options: ArgMatches,
    command: Vec<(String, Vec<String>)>,
}

impl TrainCommand {
    /// The model's parsed options.
    pub fn options(&self) -> &ArgMatches {
        &self.options
    }

    /// Records `command` (the options of a fresh run) to be written in its run folder.
    pub fn record(&mut self, command: Vec<(String, Vec<String>)>) {
        self.command = command;
    }
}

impl FromArgMatches for TrainCommand {
    fn from_arg_matches(matches: &ArgMatches) -> Result<Self, clap::Error> {
        let (kind, options) = matches
            .subcommand()
            .ok_or_else(|| clap::Error::raw(clap::error::ErrorKind::MissingSubcommand, "a model to train"))?;
        Ok(TrainCommand { kind: kind.to_string(), options: options.clone(), command: Vec::new() })
    }

    fn update_from_arg_matches(&mut self, matches: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(matches)?;
        Ok(())
    }
}

impl Subcommand for TrainCommand {
    fn augment_subcommands(cmd: clap::Command) -> clap::Command {
        cmd.subcommands(zoo_models::MODELS.iter().map(|m| m.train_command())).subcommand_required(true)
    }

    fn augment_subcommands_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_subcommands(cmd)
    }

    fn has_subcommand(name: &str) -> bool {
        zoo_models::find(name).is_some()
    }
}

/// Runs a `zoo train` subcommand.
pub fn run(cmd: TrainCommand) -> anyhow::Result<()> {
    let model = zoo_models::find(&cmd.kind).ok_or_else(|| anyhow::anyhow!("no model `{}`", cmd.kind))?;
    model.train(&cmd.options, cmd.command).map_err(|e| anyhow::anyhow!(e))
}
