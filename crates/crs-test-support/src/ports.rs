//! UDP ports for the tests' CAN-over-UDP buses that no two tests can share, whatever else runs
//! on the host (other test binaries, other checkouts' CI, a `crs sim`).
//!
//! A port derived from the process id (`20000 + pid % 20000`) collides when two processes'
//! ids agree modulo the range, and a fixed port collides with every other run of the same test.
//! Here the kernel hands out the port: [`reserve_udp_port`] binds a unicast UDP socket to
//! `127.0.0.1:0` WITHOUT `SO_REUSEADDR` and keeps it open. While the returned [`UdpPort`] lives,
//! no other reservation (in any process) can be given the same number. The stack's bus sockets
//! bind the multicast group address with `SO_REUSEADDR`, which a socket on 127.0.0.1 does not
//! block, so the test's own processes open the bus on the reserved port normally. The tests
//! use the groups of [`TEST_GROUPS`], which nothing else uses (the stack's own `auto` bus is
//! 239.255.70.9 with a port from its pid), so nobody outside the reservations can join the same
//! group and port either.

use std::net::UdpSocket;

/// Multicast groups the tests' buses use with reserved ports (one per test file, by
/// convention): 239.255.71.1 … 239.255.71.254.
pub const TEST_GROUPS: &str = "239.255.71.0/24";

/// A reserved UDP port; the reservation ends when this is dropped (keep it alive for the
/// whole run of the bus).
#[derive(Debug)]
pub struct UdpPort {
    _hold: UdpSocket,
    port: u16,
}

impl UdpPort {
    pub fn port(&self) -> u16 {
        self.port
    }

    /// `udpbus:239.255.71.<group>:<port>`, the `--transport` of a stack run on this port.
    pub fn udpbus(&self, group: u8) -> String {
        format!("udpbus:239.255.71.{group}:{}", self.port)
    }
}

/// Reserves a UDP port no other reservation can get while the result lives (see the module).
pub fn reserve_udp_port() -> UdpPort {
    let hold = UdpSocket::bind("127.0.0.1:0").expect("bind 127.0.0.1:0 to reserve a UDP port");
    let port = hold.local_addr().expect("the reserved port").port();
    UdpPort { _hold: hold, port }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reservations_never_share_a_port_and_the_bus_still_opens_on_it() {
        let held: Vec<UdpPort> = (0..200).map(|_| reserve_udp_port()).collect();
        let mut ports: Vec<u16> = held.iter().map(UdpPort::port).collect();
        ports.sort();
        ports.dedup();
        assert_eq!(ports.len(), held.len());
        // A multicast receiver as the bus opens it (group address, SO_REUSEADDR) binds on a
        // reserved port; a second plain reservation of that exact port is refused.
        let p = held[0].port();
        let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::DGRAM, None).unwrap();
        s.set_reuse_address(true).unwrap();
        let group = std::net::SocketAddrV4::new(std::net::Ipv4Addr::new(239, 255, 71, 250), p);
        s.bind(&group.into())
            .expect("bus socket on a reserved port");
        assert!(UdpSocket::bind(("127.0.0.1", p)).is_err());
        assert_eq!(held[0].udpbus(3), format!("udpbus:239.255.71.3:{p}"));
    }
}
