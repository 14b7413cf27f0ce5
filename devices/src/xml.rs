//! Reading numbers and elements of the XML files EtherCAT tools write (ESI,
//! ENI): numbers decimal, C hex (`0x1c12`) or ESI hex (`#x1c12`).

/// Reads an ESI number: `#x1A`, `0x1A`, `1A` with a hex prefix only, or
/// decimal.
pub fn parse_number(text: &str) -> Option<u64> {
    let t = text.trim();
    if let Some(h) = t
        .strip_prefix("#x")
        .or_else(|| t.strip_prefix("#X"))
        .or_else(|| t.strip_prefix("0x"))
        .or_else(|| t.strip_prefix("0X"))
    {
        u64::from_str_radix(h, 16).ok()
    } else {
        t.parse::<i64>().ok().map(|v| v as u64)
    }
}
