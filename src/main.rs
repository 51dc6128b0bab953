fn main() -> std::process::ExitCode {
    fibrefit::command_line()
}
