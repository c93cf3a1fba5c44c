//! An independent reader of a running hvs: opens `hvs/<instance>/decisions` with plain
//! iceoryx2 (not hvs's wrappers: the way a client of its own would) and prints the next N
//! decisions, one line each, read in place from shared memory.
//!
//! ```sh
//! ./target/release/hvs run &            # the simulated robot
//! cargo run --release -p hvs-shared --example read_decisions -- --instance default --count 5
//! ```
//!
//! The service settings (history, buffers, safe overflow) must match what hvs created:
//! they are the topic's constants in `hvs_shared::topics` (docs/ipc.md lists them).

use std::time::{Duration, Instant};

use hvs_shared::messages::{Decision, IntersectionType, MotionCommand};
use hvs_shared::topics;
use iceoryx2::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut instance = "default".to_string();
    let mut count = 5u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--instance" => instance = args.next().ok_or("--instance needs a name")?,
            "--count" => count = args.next().ok_or("--count needs N")?.parse()?,
            other => {
                return Err(
                    format!("unknown argument {other:?} (--instance NAME --count N)").into(),
                );
            }
        }
    }
    let topic = topics::DECISIONS;
    let service = topic.service_name(&instance);
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let name: ServiceName = service.as_str().try_into()?;
    let port = node
        .service_builder(&name)
        .publish_subscribe::<Decision>()
        .max_publishers(topic.max_publishers)
        .max_subscribers(topic.max_subscribers)
        .history_size(topic.history)
        .subscriber_max_buffer_size(topic.max_buffer)
        .subscriber_max_borrowed_samples(topic.max_borrowed)
        .enable_safe_overflow(true)
        .open()
        .map_err(|e| {
            format!(
                "cannot open {service} (is `hvs run` running with instance {instance:?}?): {e:?}"
            )
        })?;
    let subscriber = port.subscriber_builder().create()?;
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut seen = 0;
    while seen < count {
        if Instant::now() > deadline {
            return Err(
                format!("only {seen} of {count} decisions on {service} within 30 s").into(),
            );
        }
        match subscriber.receive()? {
            Some(sample) => {
                let d = sample.payload();
                println!(
                    "frame {} command {} intersection {} walls L {:.2} F {:.2} R {:.2} policy {}",
                    d.frame_id,
                    MotionCommand::from_code(d.command).label(),
                    IntersectionType::from_code(d.intersection).label(),
                    d.wall_left,
                    d.wall_front,
                    d.wall_right,
                    d.policy
                );
                seen += 1;
            }
            None => {
                if node.wait(Duration::from_millis(5)).is_err() {
                    break;
                }
            }
        }
    }
    Ok(())
}
