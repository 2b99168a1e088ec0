"""The commands: the `ptrace` CLI (cli, its flags in options and cli_camera) and the browser
viewer (view and its view_* modules, the page view_page.html)."""
