# syntax=docker/dockerfile:1
# The ground station image: service, simulator, recorder (`groundstation serve|sim|record`).
#   docker build -t groundstation .
#   docker compose up                  # zenohd + groundstation (docker-compose.yml)
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PATH=/opt/venv/bin:$PATH

# An unprivileged user owns nothing but its state directory.
RUN groupadd --system --gid 10001 groundstation \
    && useradd --system --uid 10001 --gid groundstation --no-create-home \
       --home-dir /var/lib/groundstation --shell /usr/sbin/nologin groundstation \
    && install -d -o groundstation -g groundstation /var/lib/groundstation

WORKDIR /opt/groundstation

# Dependencies first (cached while only the code changes): every one pinned with its hash.
COPY requirements-runtime.lock ./
RUN python -m venv /opt/venv \
    && pip install --require-hashes -r requirements-runtime.lock

# Then the package itself, without touching the pinned dependencies.
COPY pyproject.toml README.md ./
COPY groundstation ./groundstation
RUN pip install --no-deps --no-build-isolation . \
    && rm -rf /opt/groundstation/build

COPY config /etc/groundstation

USER groundstation:groundstation
WORKDIR /var/lib/groundstation

# 8080: dashboard. The zenoh session is a client of the router: no port of its own.
EXPOSE 8080

ENTRYPOINT ["groundstation"]
CMD ["serve", "--config", "/etc/groundstation/reel.toml", "--headless"]
