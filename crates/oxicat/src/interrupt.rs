//! Ctrl-C for the verbs that must do something on it: `sim` and `record` stop and finish
//! (a flag they poll), `sii-write` says that the EEPROM is half written and how to restore
//! it. One process-wide handler (the `ctrlc` crate allows one), installed on first use;
//! without a registered action it ends the process as SIGINT would (exit status 130), and a
//! second Ctrl-C always does.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// What a Ctrl-C does now.
enum Action {
    /// End the process (exit status 130), as without a handler.
    Exit,
    /// Set the flag (the verb stops and finishes).
    Stop(Arc<AtomicBool>),
    /// Print the message on standard error, then end the process.
    Say(String),
}

fn action() -> &'static Mutex<Action> {
    static A: OnceLock<Mutex<Action>> = OnceLock::new();
    A.get_or_init(|| Mutex::new(Action::Exit))
}

fn install() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        // Fails only when another handler is set (a test harness): then Ctrl-C keeps its
        // default, which ends the process.
        let _ = ctrlc::set_handler(|| {
            let a = action().lock().unwrap_or_else(|e| e.into_inner());
            match &*a {
                Action::Stop(flag) if !flag.swap(true, Ordering::SeqCst) => {}
                Action::Say(m) => {
                    eprintln!("\noxicat: interrupted: {m}");
                    std::process::exit(130)
                }
                _ => std::process::exit(130),
            }
        });
    });
}

/// While alive, Ctrl-C does what it was registered for; dropped, Ctrl-C ends the process.
pub struct Guard(());

impl Drop for Guard {
    fn drop(&mut self) {
        *action().lock().unwrap_or_else(|e| e.into_inner()) = Action::Exit;
    }
}

/// Ctrl-C sets `flag` (a second Ctrl-C ends the process).
pub fn stop_on_ctrl_c(flag: Arc<AtomicBool>) -> Guard {
    install();
    *action().lock().unwrap_or_else(|e| e.into_inner()) = Action::Stop(flag);
    Guard(())
}

/// Ctrl-C prints `message` and ends the process.
pub fn say_on_ctrl_c(message: String) -> Guard {
    install();
    *action().lock().unwrap_or_else(|e| e.into_inner()) = Action::Say(message);
    Guard(())
}
