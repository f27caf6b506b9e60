use clap::Parser;
use logsh::cli::{Cli, Command};

fn main() {
    quiet_mesa_device_select();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Shade(args) => logsh::run::shade(&args),
        Command::Reference(args) => logsh::run::reference(&args),
        Command::Sweep(args) => logsh::run::sweep(&args),
        Command::Example(args) => logsh::run::example(&args),
        Command::Bench(args) => logsh::run::bench(&args),
        Command::Render(args) => logsh::run::render(&args),
        Command::Info(args) => logsh::run::info(&args),
        Command::Relight(args) => logsh::run::relight(&args),
        Command::View(args) => logsh::run::view(&args),
    };
    if let Err(error) = result {
        eprintln!("error: {error:#}");
        std::process::exit(1);
    }
}

/// Mesa's Vulkan device-select layer connects to a Wayland display to order the adapters,
/// and without `XDG_RUNTIME_DIR` (a shell over ssh, a farm job, a container) libwayland
/// prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." once per
/// instance, which reads like an error of logsh's own. logsh picks its adapter itself
/// (`--device`), so there the layer is switched off, unless the user steers it.
fn quiet_mesa_device_select() {
    let unset = |name: &str| std::env::var_os(name).is_none();
    if unset("XDG_RUNTIME_DIR") && unset("NODEVICE_SELECT") && unset("MESA_VK_DEVICE_SELECT") {
        // Before any other thread exists: nothing else reads the environment yet.
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}
