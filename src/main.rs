use std::process::ExitCode;

fn main() -> ExitCode {
    match fibrefit::cli::run(std::env::args_os()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if !e.is::<fibrefit::cli::UsageError>() {
                eprintln!("error: {e:#}");
            }
            ExitCode::from(2)
        }
    }
}
