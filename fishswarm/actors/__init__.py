"""The async actors (fish, world, channel, observer) and their Zenoh/trio plumbing."""
