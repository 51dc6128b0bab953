use std::process::ExitCode;

fn main() -> ExitCode {
    fibrefit::export::atomic::install_signal_cleanup();
    let outcome = fibrefit::cli::run(std::env::args_os());
    if fibrefit::load::input::interrupted() {
        // SIGINT/SIGTERM came (a wait it stopped may be why the run failed): its handler
        // cleans up and exits 130; the run's own outcome is not the exit code
        loop {
            std::thread::sleep(std::time::Duration::from_secs(1));
        }
    }
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        // a reader that stops early (`| head`) is not an error
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            if !e.is::<fibrefit::cli::UsageError>() {
                // a closed or full stderr loses the message, not the exit code
                use std::io::Write;
                let _ = writeln!(std::io::stderr(), "error: {e:#}");
            }
            ExitCode::from(2)
        }
    }
}
