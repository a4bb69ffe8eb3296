# Shared by scripts/soak and scripts/reconnect-bench: a rig without cameras for the daemon,
# Aravis's fake GigE camera on 127.0.0.1 as the colour camera and the fixture session's depth
# frames at camera pace as the depth camera. Source it from the repository's root.

# Installs what is missing and builds the release binary; as root, then runs the calling
# script again (with the same arguments) in its own network namespace with only loopback, so
# that nothing it does can reach a network or clash with another fake camera, and in a mount
# namespace of its own (a file system it mounts is seen by it alone, and goes with it).
#   fake_rig_enter SCRIPT ARGS...
fake_rig_enter() {
    if [ -n "${FAKE_RIG_IN_NETNS:-}" ]; then
        ip link set lo up
        return
    fi
    bash scripts/setup.sh
    cargo build --release --locked --quiet
    if [ "$(id -u)" = 0 ]; then
        exec env FAKE_RIG_IN_NETNS=1 unshare --net --mount --propagation private bash "$@"
    fi
}

# Writes the rig config; DEPTH_EXTRA, if given, is added to the [depth] table.
#   fake_rig_config FILE OUTPUT_DIR RECORD CHUNK_MINUTES [DEPTH_EXTRA]
fake_rig_config() {
    cat >"$1" <<CONFIG
[depth]
backend = "session"
path = "$PWD/fixtures/sessions/synthetic-small"
${5:-}

[color]
backend = "aravis"
address = "127.0.0.1"
pixel_format = "mono8"
region = [0, 0, 320, 256]
fps = 30

[output]
dir = "$2"
record = "$3"
chunk_minutes = $4
CONFIG
}

# Starts the fake camera; its process id in $fake_camera.
fake_rig_camera() {
    arv-fake-gv-camera-0.8 -i 127.0.0.1 -s MP-FAKE-RIG >/dev/null 2>&1 &
    fake_camera=$!
}
