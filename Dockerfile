# nao-formation: one image for the router, the world, the observer and the agents
# (docs/design.md §5); no credentials inside (docker-compose.yml mounts them as secrets).
#   docker compose build                      # from python:3.11-slim
#   docker-compose build --build-arg BASE_IMAGE=localhost/nao-base:bookworm   # local base
# The base needs python3 with the venv module and ca-certificates (Debian bookworm or
# python:3.11-slim). Behind a TLS-inspecting proxy, pass its CA (public PEM text) so pip
# can reach PyPI:  --build-arg EXTRA_CA_CERT="$(cat /usr/local/share/ca-certificates/*.crt)"
ARG BASE_IMAGE=python:3.11-slim
FROM ${BASE_IMAGE}
ARG EXTRA_CA_CERT=""

ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    VIRTUAL_ENV=/opt/venv \
    PATH=/opt/venv/bin:$PATH \
    MPLBACKEND=Agg \
    PIP_CERT=/etc/ssl/certs/ca-certificates.crt

# iptables: fault injection inside an agent container (LOSS=0.2 in docker-compose.yml).
# libegl1 libegl-mesa0 libgl1-mesa-dri: the cameras' EGL renderer (sim/camera/renderer.py; Mesa's
# llvmpipe on the CPU), else the world falls back to TinyRenderer.
RUN apt-get update -qq \
    && apt-get install -y -qq --no-install-recommends iptables \
        libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null \
    && rm -rf /var/lib/apt/lists/*
RUN if [ -n "$EXTRA_CA_CERT" ]; then \
        printf '%s\n' "$EXTRA_CA_CERT" > /usr/local/share/ca-certificates/extra-ca.crt \
        && update-ca-certificates; \
    fi \
    && python3 -m venv /opt/venv
WORKDIR /app

# Dependencies first, in their own layer: editing the code (or the README, which the
# package metadata names) does not reinstall numpy & co.
COPY pyproject.toml ./
RUN mkdir -p agent sim tools \
    && touch README.md agent/__init__.py sim/__init__.py tools/__init__.py \
    && pip install . \
    && pip uninstall -y nao-formation \
    && rm -rf agent sim tools build *.egg-info

# The project itself.
COPY README.md ./
COPY agent ./agent
COPY sim ./sim
COPY tools ./tools
RUN pip install --no-deps . && rm -rf build *.egg-info \
    && python -c "import zenoh, numpy, scipy, cv2, msgpack, pybullet, agent.wire"

# No default role: docker-compose.yml sets the command (and the credentials, mounted as
# secrets under /run/secrets/fleet) of each service.
CMD ["python", "-m", "tools.router", "--credentials", "/run/secrets/fleet"]
