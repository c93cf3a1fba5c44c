//! hvs probe: read-only inspection of a running pipeline from a separate process.
//!
//! The probe attaches to an instance's topics as an ordinary iceoryx2 subscriber (every topic
//! reserves subscriber slots for probes and uses safe overflow, so a slow or killed probe never
//! stalls a publisher). Until the probe commands exist, `hvs status` shows the supervisor's
//! view of every stage.
