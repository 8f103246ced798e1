# One image for the world and every peer: the same `sensornet` CLI as on a laptop.
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY tracking ./tracking
COPY protocol ./protocol
COPY peers ./peers
COPY sim ./sim
COPY sensornet ./sensornet
RUN pip install --no-cache-dir . && rerun analytics disable >/dev/null 2>&1 || true
ENTRYPOINT ["sensornet"]
