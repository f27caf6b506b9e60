use clap::Parser;
use logsh::cli::{Cli, Command};

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Shade(args) => logsh::run::shade(&args),
        Command::Reference(args) => logsh::run::reference(&args),
        Command::Sweep(args) => logsh::run::sweep(&args),
        Command::Example(args) => logsh::run::example(&args),
        Command::Bench(args) => logsh::run::bench(&args),
        Command::Render(args) => logsh::run::render(&args),
        Command::Info(args) => logsh::run::info(&args),
    };
    if let Err(error) = result {
        eprintln!("error: {error:#}");
        std::process::exit(1);
    }
}
