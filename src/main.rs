//! The `tumble` command-line tool: see [`cli`] (one module per command).

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
