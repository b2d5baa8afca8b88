//! `acps`: the command line of Active Contextual Policy Search ([`acps::main`]).

fn main() -> std::process::ExitCode {
    std::process::ExitCode::from(acps::main(std::env::args_os()))
}
