"""client.py: one HTTP request to a server the tests started on loopback, its body read."""

import http.client


def request(port, target, headers=None, method="GET", timeout=120):
    """The response to METHOD TARGET on 127.0.0.1:PORT, with its body in r.body."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout)
    conn.request(method, target, headers=headers or {})
    r = conn.getresponse()
    r.body = r.read()
    conn.close()
    return r
