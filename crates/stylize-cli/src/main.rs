fn main() {
    eprintln!("stylize: no commands yet");
    std::process::exit(2);
}
