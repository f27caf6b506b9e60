use clap::Parser;
use logsh::cli::{Cli, Command};

fn main() {
    quiet_mesa_device_select();
    end_quietly_on_a_closed_pipe();
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

/// `logsh info FILE | head -3` closes logsh's standard output early. Rust ignores SIGPIPE,
/// so the next write fails and `println!` panics with a backtrace; C tools end quietly
/// there, killed by the signal. logsh does the same: SIGPIPE back to its default action.
/// Sockets are unaffected (the standard library sends with `MSG_NOSIGNAL` on Linux and
/// sets `SO_NOSIGPIPE` on macOS), so the viewer's server survives a client that leaves.
fn end_quietly_on_a_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: before any other thread exists; SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
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
