# One image for every voicectl service; compose.yaml picks the service by command.
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    VOICECTL_DATA=/data

# espeak-ng: British and guessed pronunciations for the speech recogniser.
RUN apt-get update \
    && apt-get install -y --no-install-recommends espeak-ng \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY voicectl ./voicectl
COPY orders ./orders
# Editable, like scripts/up: the services find the shipped orders next to the code.
RUN pip install --no-cache-dir -e ".[stt]" \
    && useradd --create-home --uid 1000 voicectl \
    && mkdir -p /data && chown voicectl /data
USER voicectl
VOLUME ["/data"]
ENTRYPOINT ["voicectl"]
CMD ["--help"]
