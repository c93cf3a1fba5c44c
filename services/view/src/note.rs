//! The view stage's status note (`hvs status`, the supervisor's table): the ports it serves
//! on, written here and read back here, so that tests and benchmarks that must find a port
//! chosen at run time (`bind = "127.0.0.1:0"`) parse what the stage wrote.

/// What precedes the WebSocket port in the note.
const WS_TAG: &str = "ws :";
/// What precedes the web page's port in the note.
const HTTP_TAG: &str = "http :";

/// The WebSocket side of the note: the port and the client count, or why it is not serving.
pub fn ws_part(serving: Result<(u16, usize), &str>) -> String {
    match serving {
        Ok((port, clients)) => format!("{WS_TAG}{port} clients {clients}"),
        Err(why) => why.to_string(),
    }
}

/// The web page side of the note: the port, or why it is not serving.
pub fn http_part(serving: Result<u16, &str>) -> String {
    match serving {
        Ok(port) => format!("{HTTP_TAG}{port}"),
        Err(why) => why.to_string(),
    }
}

fn port_after(note: &str, tag: &str) -> Option<u16> {
    note.split(tag)
        .nth(1)?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The WebSocket port a note names, once the server is up.
pub fn ws_port(note: &str) -> Option<u16> {
    port_after(note, WS_TAG)
}

/// The web page's port a note names, once its server is up.
pub fn http_port(note: &str) -> Option<u16> {
    port_after(note, HTTP_TAG)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ports_read_back_what_was_written() {
        let note = format!("{} {}", ws_part(Ok((41234, 2))), http_part(Ok(8766)));
        assert_eq!(
            (ws_port(&note), http_port(&note)),
            (Some(41234), Some(8766))
        );
        let down = format!(
            "{} {}",
            ws_part(Err("ws 127.0.0.1:8765: address in use")),
            http_part(Ok(8766))
        );
        assert_eq!((ws_port(&down), http_port(&down)), (None, Some(8766)));
    }
}
