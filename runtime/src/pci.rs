//! A device's PCI address, as `nvidia-smi` and `lspci -D` print it.

use std::fmt;

/// A PCI address, domain:bus:device.function (`VK_EXT_pci_bus_info`; `nvidia-smi` and `lspci -D`
/// print it so).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct PciAddress {
    pub domain: u32,
    pub bus: u32,
    pub device: u32,
    pub function: u32,
}

impl fmt::Display for PciAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04x}:{:02x}:{:02x}.{:x}", self.domain, self.bus, self.device, self.function)
    }
}

impl PciAddress {
    /// `0000:65:00.0`, or `65:00.0` in domain 0.
    pub(crate) fn parse(s: &str) -> Option<PciAddress> {
        let (head, function) = s.rsplit_once('.')?;
        let parts: Vec<&str> = head.split(':').collect();
        let (domain, bus, device) = match parts[..] {
            [domain, bus, device] => (domain, bus, device),
            [bus, device] => ("0", bus, device),
            _ => return None,
        };
        let hex = |t: &str| u32::from_str_radix(t, 16).ok();
        Some(PciAddress { domain: hex(domain)?, bus: hex(bus)?, device: hex(device)?, function: hex(function)? })
    }
}
