# voicectl's images, one per role (docs/deploy.md, "Containers"); compose.yaml picks the
# service by command:
#   docker build --target robot -t voicectl-robot:latest .   the executor and nothing else
#   docker build --target host -t voicectl:latest .          every other service
# `docker build .` builds the host image (the last stage).

FROM python:3.11-slim AS base
ENV PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    VOICECTL_DATA=/data
RUN useradd --create-home --uid 1000 voicectl \
    && mkdir -p /data && chown voicectl /data

# The wheel, built once for both roles. Installed, not editable: the shipped orders
# travel inside it, so the image needs no source tree.
FROM base AS wheel
WORKDIR /src
COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY voicectl ./voicectl
COPY orders ./orders
RUN pip wheel --no-deps --wheel-dir /wheels .

# The robot: the core dependencies only (Zenoh, msgspec, numpy, Pillow, PyYAML, rosbags):
# no web server, no speech engine, no fuzzy matcher.
FROM base AS robot
COPY --from=wheel /wheels /wheels
RUN pip install /wheels/voicectl-*.whl && rm -rf /wheels
USER voicectl
WORKDIR /home/voicectl
VOLUME ["/data"]
ENTRYPOINT ["voicectl"]
CMD ["executor", "--help"]

# The host: every service, with the embedded speech engine. VOICECTL_EXTRAS=host,vosk
# adds Vosk (compose.vosk.yaml does).
FROM base AS host
# espeak-ng: British and guessed pronunciations for the speech recogniser.
RUN apt-get update \
    && apt-get install -y --no-install-recommends espeak-ng \
    && rm -rf /var/lib/apt/lists/*
ARG VOICECTL_EXTRAS=host
COPY --from=wheel /wheels /wheels
RUN pip install "$(echo /wheels/voicectl-*.whl)[${VOICECTL_EXTRAS}]" && rm -rf /wheels
USER voicectl
WORKDIR /home/voicectl
VOLUME ["/data"]
ENTRYPOINT ["voicectl"]
CMD ["--help"]
