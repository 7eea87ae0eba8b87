mod error;
mod video;
fn main() {}
