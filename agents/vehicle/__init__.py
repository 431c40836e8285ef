"""One vehicle of the fleet: its configuration, frame clock and camera, team-mates' views, roles and per-frame step."""
