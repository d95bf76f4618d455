"""Where the web page listens (``--ui HOST:PORT``) and whether it needs a token."""

from __future__ import annotations

import ipaddress
import re

TOKEN_PATTERN = re.compile(r"[A-Za-z0-9._~-]{8,128}")


def parse_bind(text: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST:PORT`` (``[::1]:8080`` for IPv6; port 0: any free port); ValueError says why."""
    m = re.fullmatch(r"\[([0-9A-Fa-f:.]+)\]:(\d{1,5})|([^:\[\]\s]+):(\d{1,5})", text)
    if m is None:
        raise ValueError("expected HOST:PORT, e.g. 127.0.0.1:8080 or 0.0.0.0:8080")
    host, port = (m[1], m[2]) if m[1] else (m[3], m[4])
    if int(port) > 65535:
        raise ValueError(f"port {port} is not 0..65535")
    return host, int(port)


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.0.0.0/8, ::1, localhost): then no token is needed."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: it may resolve beyond this machine
        return False


def check_token(token: str) -> None:
    """ValueError unless ``token`` is 8–128 URL-safe characters (it travels in the page's URL)."""
    if not TOKEN_PATTERN.fullmatch(token):
        raise ValueError("expected 8-128 characters of A-Z a-z 0-9 . _ ~ - (it goes into a URL)")
