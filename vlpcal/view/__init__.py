"""The live page (docs/view.md): what the cameras see, where the LEDs and robots are, and the
plan they are seen on — in a browser, served by vlpcal itself (no build step, no outside URL).

:mod:`.hub` is the one place a running command puts what it sees (never waiting on a page);
:mod:`.scene` turns a deployment or site into what the page draws; :mod:`.server` serves the
page and streams the hub to it. Only :mod:`.server` imports the web framework."""

from .hub import ViewHub

__all__ = ["ViewHub"]
