"""The companion's control surface: the QAPI and the layers above it over HTTP, one router per resource
(:mod:`companion.http.app` lists the routes). The error shape and the bearer-token check are the ground
service's too (:mod:`taskflight_common.httpapi`)."""

from companion.http.app import create_app
from companion.http.server import ControlServer, is_loopback

__all__ = ["ControlServer", "create_app", "is_loopback"]
