# One image for the world and every peer: the same `sensornet` CLI as on a laptop.
# Stage 1 builds the project's wheel; the image itself carries only the installed package and
# its dependencies (no sources, tests, benchmarks or docs).
FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY tracking ./tracking
COPY protocol ./protocol
COPY peers ./peers
COPY sim ./sim
COPY sensornet ./sensornet
RUN pip wheel --no-cache-dir --no-deps --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 RERUN_ANALYTICS=0 \
    PIP_DISABLE_PIP_VERSION_CHECK=1
COPY --from=build /wheels /wheels
# A failed install fails the build (only turning Rerun's analytics off may fail, in its own
# parentheses), and the installed command must run.
RUN pip install --no-cache-dir /wheels/*.whl \
    && rm -rf /wheels \
    && (rerun analytics disable >/dev/null 2>&1 || true) \
    && sensornet --help >/dev/null
WORKDIR /runs
ENTRYPOINT ["sensornet"]
