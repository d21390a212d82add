//! One module per `waymark` subcommand: its arguments and what it runs.

pub mod bench;
pub mod benchmark;
pub mod demo;
pub mod eval;
pub mod evidence;
pub mod hmm;
pub mod replay;
pub mod results;
pub mod route;
pub mod sim_export;
pub mod simulate;
pub mod site;
pub mod survey;
pub mod view;
