# crossway: one image for the learner, the actors and the router; entry point `crossway`.
# CPU torch. For a GPU learner build with TORCH_INDEX_URL pointing at a CUDA wheel index and run
# the learner on a GPU host (actors stay on CPU); see docs/deploy.md.
FROM python:3.11-slim-bookworm AS build
ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu
RUN apt-get update && apt-get install -y --no-install-recommends gcc libcairo2-dev pkg-config \
    && rm -rf /var/lib/apt/lists/*
RUN python -m venv /opt/crossway
ENV PATH=/opt/crossway/bin:$PATH
# torch first, from the CPU index, in its own layer: it changes least and weighs most
RUN pip install --no-cache-dir --index-url "$TORCH_INDEX_URL" "torch==2.13.0"
COPY pyproject.toml README.md ./
COPY simcore simcore
COPY algo algo
COPY protocol protocol
COPY actors actors
COPY learner learner
COPY evaluation evaluation
COPY crossway crossway
RUN pip install --no-cache-dir .

FROM python:3.11-slim-bookworm
RUN apt-get update && apt-get install -y --no-install-recommends libcairo2 \
    && rm -rf /var/lib/apt/lists/* && useradd --create-home crossway
COPY --from=build /opt/crossway /opt/crossway
ENV PATH=/opt/crossway/bin:$PATH PYTHONUNBUFFERED=1
USER crossway
WORKDIR /home/crossway
ENTRYPOINT ["crossway"]
CMD ["--help"]
