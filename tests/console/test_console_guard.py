"""Who may do what: addresses, the Host and Origin rules, control with a token."""

import pytest

from afa.console.guard import ControlGuard, host_name, is_loopback, parse_address


@pytest.mark.parametrize("text, expected", [
    ("8765", ("127.0.0.1", 8765)),
    (":8765", ("127.0.0.1", 8765)),
    ("0", ("127.0.0.1", 0)),
    ("0.0.0.0:9000", ("0.0.0.0", 9000)),
    ("localhost:1", ("localhost", 1)),
    ("[::1]:8765", ("::1", 8765)),
])
def test_console_addresses(text, expected):
    assert parse_address(text) == expected


@pytest.mark.parametrize("text, message", [
    ("http", r"not \[HOST:\]PORT"),
    ("::1:8765", "brackets"),
    ("70000", "outside 0..65535"),
])
def test_bad_console_addresses_say_why(text, message):
    with pytest.raises(ValueError, match=message):
        parse_address(text)


def test_loopback_hosts():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


def test_on_loopback_only_this_servers_host_and_own_page_are_accepted():
    guard = ControlGuard("127.0.0.1", 8765)
    assert guard.check_request("127.0.0.1:8765", None) is None
    assert "not this console" in guard.check_request("192.168.1.5:8765", None)
    assert "not this console" in guard.check_request("127.0.0.1:9000", None)
    assert guard.check_request("localhost:8765", "http://localhost:8765") is None
    # DNS rebinding: a foreign name that resolves to 127.0.0.1
    assert "not this console" in guard.check_request("evil.example:8765", None)
    # another site open in the same browser
    assert "not accepted" in guard.check_request("127.0.0.1:8765", "http://evil.example")
    assert "opaque" in guard.check_request("127.0.0.1:8765", "null")
    assert guard.check_request(None, None) == "no Host header"


def test_beyond_loopback_ip_addresses_and_listed_names_but_only_the_own_origin():
    guard = ControlGuard("0.0.0.0", 8765)
    for host in ("192.168.1.5:8765", "10.0.0.7", "127.0.0.1:8765", "[fd00::5]:8765",
                 "[::1]:9000"):  # any port: a forwarded one too
        assert guard.check_request(host, f"http://{host}") is None, host
    # DNS rebinding: the attacker's name, resolving to this machine, and its own page
    assert "not this console" in guard.check_request("attacker.example:8765",
                                                     "http://attacker.example:8765")
    assert "--console-host-name" in guard.check_request("vehicle.lan:8765", None)
    for odd in ("1.2.3.4@evil.example", "[evil.example]:8765", "1.2.3.4:8765/x", ""):
        assert guard.check_request(odd, None) is not None, odd
    named = ControlGuard("0.0.0.0", 8765, names=frozenset({"vehicle.lan"}))
    assert named.check_request("Vehicle.LAN:8765", "http://vehicle.lan:8765") is None
    assert named.check_request("vehicle.lan:8765", "http://other.lan:8765") is not None
    assert named.check_request("other.lan:8765", None) is not None
    # a listed name on loopback too (a proxy in front of the console)
    assert ControlGuard("127.0.0.1", 8765, names=frozenset({"vehicle.lan"})).check_request(
        "vehicle.lan", None) is None


def test_host_names_are_names_without_a_port():
    assert host_name(" Vehicle.LAN ") == "vehicle.lan"
    for bad in ("vehicle.lan:8765", "http://vehicle.lan", "a b", ""):
        with pytest.raises(ValueError, match="not a host name"):
            host_name(bad)


def test_control_needs_the_option_and_the_token_and_stop_needs_neither():
    view_only = ControlGuard("127.0.0.1", 8765, control=False)
    assert "--console-control" in view_only.check_permission("control", view_only.token)
    for permission in ("view", "stop", "replay"):
        assert view_only.check_permission(permission, None) is None
    control = ControlGuard("127.0.0.1", 8765, control=True)
    assert "token" in control.check_permission("control", None)
    assert "token" in control.check_permission("control", "guess")
    # any character a header may carry is just a wrong token
    for foreign in ("é", "\udcff", control.token + "é"):
        assert "token" in control.check_permission("control", foreign)
    assert control.check_permission("control", control.token) is None
    assert ControlGuard("127.0.0.1", 1).token != control.token  # per run
