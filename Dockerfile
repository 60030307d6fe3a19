# voicectl's images, one per role (docs/deploy.md, "Containers"); compose.yaml picks the
# service by command:
#   docker build --target robot -t voicectl-robot:latest .   the executor and nothing else
#   docker build --target listen -t voicectl-listen:latest .  the robot's ear and voice
#   docker build --target host -t voicectl:latest .          every other service
# `docker build .` builds the host image (the last stage). Build with BuildKit
# (DOCKER_BUILDKIT=1, or any docker with buildx).
#
# BASE_IMAGE: a Debian 12 (bookworm) with Python 3.11 and its venv module. Where Docker
# Hub cannot be reached, scripts/base-image makes one from Debian packages.
# Behind a proxy that intercepts TLS, pip is handed the proxy's CA bundle as a build
# secret, which never becomes a layer: --secret id=ca,src=/etc/ssl/certs/ca-certificates.crt
# (docs/deploy.md, "Behind a proxy").

ARG BASE_IMAGE=python:3.11-slim-bookworm

FROM ${BASE_IMAGE} AS base
ENV PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    VOICECTL_DATA=/data \
    VOICECTL_HEARTBEAT=/tmp/voicectl/alive \
    PATH=/opt/voicectl/bin:$PATH
# /etc/voicectl/bus: where compose.secure.yaml mounts the bus secrets, owned by the
# containers' user so that `bus-secrets` writes them as that user.
RUN useradd --create-home --uid 1000 voicectl \
    && mkdir -p /data /etc/voicectl/bus && chown voicectl /data /etc/voicectl/bus

# Each role's dependencies in a layer of its own, keyed on pyproject.toml alone: a change
# to the source rebuilds only the small layer that installs voicectl (deploy/install.py).
FROM base AS venv
# binutils: strip, for the Zenoh extension (build stages only).
RUN apt-get update \
    && apt-get install -y --no-install-recommends binutils \
    && rm -rf /var/lib/apt/lists/*
COPY pyproject.toml deploy/install.py /tmp/build/
RUN python3 -m venv /opt/voicectl

FROM venv AS robot-deps
RUN --mount=type=secret,id=ca python3 /tmp/build/install.py deps /tmp/build/pyproject.toml

FROM venv AS host-deps
# host,vosk adds Vosk (compose.vosk.yaml does).
ARG VOICECTL_EXTRAS=host
RUN --mount=type=secret,id=ca \
    python3 /tmp/build/install.py deps /tmp/build/pyproject.toml "$VOICECTL_EXTRAS"

FROM venv AS listen-deps
RUN --mount=type=secret,id=ca \
    python3 /tmp/build/install.py deps /tmp/build/pyproject.toml listen,mic

# voicectl's wheel, built once for every role. Installed, not editable: the shipped
# orders travel inside it, so the images hold no source tree.
FROM venv AS wheel
COPY README.md /tmp/build/
COPY shared /tmp/build/shared
COPY services /tmp/build/services
COPY voicectl /tmp/build/voicectl
COPY orders /tmp/build/orders
RUN --mount=type=secret,id=ca python3 /tmp/build/install.py wheel /tmp/build /tmp/wheels

FROM robot-deps AS robot-install
COPY --from=wheel /tmp/wheels /tmp/wheels
RUN python3 /tmp/build/install.py voicectl /tmp/wheels

FROM listen-deps AS listen-install
COPY --from=wheel /tmp/wheels /tmp/wheels
RUN python3 /tmp/build/install.py voicectl /tmp/wheels

FROM host-deps AS host-install
COPY --from=wheel /tmp/wheels /tmp/wheels
RUN python3 /tmp/build/install.py voicectl /tmp/wheels

# The robot: the core dependencies only (Zenoh, msgspec, rosbags for ROS 2's wire format
# and its numpy, Pillow, PyYAML): no web server, no speech engine, no fuzzy matcher.
FROM base AS robot
COPY --from=robot-install /opt/voicectl /opt/voicectl
USER voicectl
WORKDIR /home/voicectl
ENTRYPOINT ["voicectl"]
CMD ["executor", "--help"]

# A stand-in for Docker Hub's eclipse/zenoh where it cannot be pulled: voicectl's own
# router, which takes zenohd's flags (--config, --listen, --connect). Not zenohd.
FROM robot AS router
ENTRYPOINT ["voicectl", "router"]
CMD ["--listen", "tcp/0.0.0.0:7447"]

# The robot's ear and voice (`voicectl listen`): the wake phrase spotter, PortAudio for
# the sound device the container is given (libasound2-plugins: ALSA's pulse plugin, for a
# host whose sound goes through PulseAudio), espeak-ng to answer.
FROM base AS listen
RUN apt-get update \
    && apt-get install -y --no-install-recommends libportaudio2 libasound2-plugins espeak-ng \
    && apt-get clean && rm -rf /var/lib/apt/lists/*
COPY --from=listen-install /opt/voicectl /opt/voicectl
USER voicectl
WORKDIR /home/voicectl
ENTRYPOINT ["voicectl"]
CMD ["listen", "--help"]

# The host: every service, with the embedded speech engine.
FROM base AS host
# espeak-ng: British and guessed pronunciations for the speech recogniser.
RUN apt-get update \
    && apt-get install -y --no-install-recommends espeak-ng \
    && apt-get clean && rm -rf /var/lib/apt/lists/*
COPY --from=host-install /opt/voicectl /opt/voicectl
USER voicectl
WORKDIR /home/voicectl
# Moonshine's model, prepared for onnxruntime once here (services/stt/moonshine.py), not at
# every start of a container.
RUN python3 -c "from voicectl.services.stt.moonshine import prepare, weights_dir; \
from voicectl.shared.config import cache_dir; prepare(weights_dir(), cache_dir())"
ENTRYPOINT ["voicectl"]
CMD ["--help"]
