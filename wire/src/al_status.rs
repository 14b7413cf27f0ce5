//! AL status codes (register 0x0134): what a slave says when it refuses or
//! leaves a state. The text is what users see next to the code in slave
//! lists and errors.

/// The meaning of an AL status code (ETG.1000.6 Table 11, the common ones).
pub const fn al_status_text(code: u16) -> &'static str {
    match code {
        0x0000 => "no error",
        0x0001 => "unspecified error",
        0x0002 => "no memory",
        0x0011 => "invalid requested state change",
        0x0012 => "unknown requested state",
        0x0013 => "bootstrap not supported",
        0x0014 => "no valid firmware",
        0x0015 => "invalid mailbox configuration (bootstrap)",
        0x0016 => "invalid mailbox configuration",
        0x0017 => "invalid sync manager configuration",
        0x0018 => "no valid inputs available",
        0x0019 => "no valid outputs",
        0x001A => "synchronization error",
        0x001B => "sync manager watchdog",
        0x001C => "invalid sync manager types",
        0x001D => "invalid output configuration",
        0x001E => "invalid input configuration",
        0x001F => "invalid watchdog configuration",
        0x0020 => "slave needs cold start",
        0x0021 => "slave needs INIT",
        0x0022 => "slave needs PREOP",
        0x0023 => "slave needs SAFEOP",
        0x0027 => "freerun not supported",
        0x0028 => "synchronization not supported",
        0x002C => "fatal sync error",
        0x0030 => "invalid DC sync configuration",
        0x0032 => "PLL error",
        0x0035 => "invalid sync cycle time",
        0x0036 => "sync cycle time too small",
        _ => "vendor-specific or unknown AL status code",
    }
}
