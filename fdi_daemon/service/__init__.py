"""The daemon: sample loop, status socket, sd_notify/watchdog, recorder."""
