// A Coupler participant written from proto/coupler/v1/component.proto alone, in Node.js.
//
//   node participant.js [--port P] [--name NAME]      (P = 0, the default: any free port)
//
// "Scale": parameter gain (Real, start 2), input u (Real, start 0); outputs y = gain * u
// (Real) and steps (Integer, steps done in the run). It follows the protocol's rules as the
// .proto comments state them (docs/protocol.md has the table): one run at a time, the run id
// and the run secret on every call of a run (the secret compared in constant time; a call of
// the run without it is refused PERMISSION_DENIED and remembered, the owner's next call is
// ABORTED naming it), leases of at most 24 h that end a silent run, finite times, a run that
// ends with its StepStream. It serves the standard health service (SERVING once listening).
'use strict';

const crypto = require('node:crypto');
const path = require('node:path');
const grpc = require('@grpc/grpc-js');
const protoLoader = require('@grpc/proto-loader');
const { HealthImplementation } = require('grpc-health-check');

const PROTO = path.join(__dirname, '..', '..', 'proto', 'coupler', 'v1', 'component.proto');
const MAX_LEASE = 86400; // s: the ceiling of a lease
const DEFAULT_LEASE = 60; // s: the lease of an Initialize that asks for none
const status = grpc.status;

const definition = protoLoader.loadSync(PROTO, {
  keepCase: true, // run_id, run_secret, lease_seconds: the names in the .proto
  defaults: true,
  oneofs: true, // binding.value names the field that is set
});
const pb = grpc.loadPackageDefinition(definition).coupler.v1;

const args = process.argv.slice(2);
const option = (name, fallback) => {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : fallback;
};
const NAME = option('--name', 'Scale');

// Every channel is Real or Integer, so none declares ChannelDescription.max_bytes (the largest
// value of a Binary or String channel): 0, not declared, which the .proto allows. Its values
// are a few bytes a message, well within gRPC's default limits (4 MiB received), which it keeps.
// A participant with Binary or String channels would declare max_bytes for each and set its
// server's grpc.max_receive_message_length to its inputs' maxima together plus 8 MiB.
const CHANNELS = [
  { name: 'gain', causality: 'CAUSALITY_PARAMETER', type: 'VALUE_TYPE_REAL', start: 2 },
  { name: 'u', causality: 'CAUSALITY_INPUT', type: 'VALUE_TYPE_REAL', start: 0 },
  { name: 'y', causality: 'CAUSALITY_OUTPUT', type: 'VALUE_TYPE_REAL', start: 0 },
  { name: 'steps', causality: 'CAUSALITY_OUTPUT', type: 'VALUE_TYPE_INTEGER', start: 0 },
];

class Refusal extends Error {
  constructor(code, details) {
    super(details);
    this.code = code;
    this.details = details;
  }
}

let run = null; // {id, secret, lease, reached, intrusion, intrusions, timer, gain, u, steps}

function log(event, fields) {
  console.error(JSON.stringify({ event, participant: NAME, ...fields }));
}

function finite(name, value) {
  if (!Number.isFinite(value)) throw new Refusal(status.INVALID_ARGUMENT, `${name} must be finite, got ${value}`);
}

// Values of the bindings, each checked against its channel (a Real of the given causality).
function values(bindings, causality) {
  const found = {};
  for (const b of bindings) {
    const channel = CHANNELS.find((c) => c.name === b.channel && c.causality === causality);
    if (!channel) throw new Refusal(status.INVALID_ARGUMENT, `participant '${NAME}' has no ${causality} channel '${b.channel}'`);
    if (b.value !== 'real') throw new Refusal(status.INVALID_ARGUMENT, `channel '${b.channel}' expects Real, got ${b.value}`);
    finite(`channel '${b.channel}'`, b.real);
    found[b.channel] = b.real;
  }
  return found;
}

function outputs() {
  return [
    { channel: 'y', real: run.gain * run.u },
    { channel: 'steps', integer: run.steps },
  ];
}

function endRun(why) {
  if (!run) return;
  clearTimeout(run.timer);
  log('run_ended', { run_id: run.id, why });
  run = null;
}

// The lease: a run silent for `lease` seconds ends (a dead orchestrator never locks us).
function touch(active) {
  clearTimeout(active.timer);
  active.timer = setTimeout(() => {
    if (run === active) endRun(`lease expired: no call for ${active.lease} s`);
  }, active.lease * 1000);
}

function sameSecret(given, expected) {
  // constant time in the content; a secret of another length is simply wrong
  return given.length === expected.length && crypto.timingSafeEqual(given, expected);
}

function refusal(active) {
  const more = active.intrusions - 1;
  return active.intrusion + (more > 0 ? ` (${more} more such calls since)` : '');
}

// The rules every call of a run obeys; returns the active run. `peer` names the caller.
function ofTheRun(request, call, peer) {
  if (!run) throw new Refusal(status.FAILED_PRECONDITION, `${call} before Initialize: participant '${NAME}' has no run`);
  if (request.run_id !== run.id) {
    throw new Refusal(status.FAILED_PRECONDITION, `${call} for run '${request.run_id}', which is not participant '${NAME}'s active run`);
  }
  if (!sameSecret(request.run_secret, run.secret)) {
    run.intrusions += 1;
    if (!run.intrusion) {
      const how = request.run_secret.length ? 'with a wrong secret' : "without this run's secret";
      run.intrusion = `${NAME} refused the run: a call ${how} arrived from ${peer} (${call} at t=${run.reached} s); the run is no longer trusted`;
    }
    log('run_intrusion', { run_id: run.id, peer, call });
    throw new Refusal(status.PERMISSION_DENIED, `${call} refused: it names participant '${NAME}'s active run but does not carry that run's secret (run_secret, docs/protocol.md); the run's owner will be told`);
  }
  return run;
}

function step(request, peer) {
  const active = ofTheRun(request, 'DoStep', peer);
  if (active.intrusion) throw new Refusal(status.ABORTED, refusal(active));
  if (!(request.step_size > 0) || !Number.isFinite(request.step_size) || !Number.isFinite(request.current_time)) {
    throw new Refusal(status.INVALID_ARGUMENT, `step_size must be finite and positive and current_time finite, got step_size=${request.step_size}, current_time=${request.current_time}`);
  }
  const inputs = values(request.inputs, 'CAUSALITY_INPUT');
  if ('u' in inputs) active.u = inputs.u;
  active.steps += 1;
  active.reached = request.current_time + request.step_size;
  touch(active);
  return { outputs: outputs() };
}

// Unary handlers answer the callback with the result or the refusal.
function unary(handler) {
  return (call, callback) => {
    try {
      callback(null, handler(call.request, call.getPeer()));
    } catch (error) {
      if (!(error instanceof Refusal)) throw error;
      callback({ code: error.code, details: error.details });
    }
  };
}

const service = {
  Describe: unary(() => ({
    name: NAME,
    implementation: 'examples/participant-node (Node.js, @grpc/grpc-js)',
    capabilities: { streaming: true, variable_step_size: true },
    channels: CHANNELS.map((c) => ({
      name: c.name,
      causality: c.causality,
      type: c.type,
      start: c.type === 'VALUE_TYPE_REAL' ? { channel: c.name, real: c.start } : { channel: c.name, integer: c.start },
    })),
  })),

  Initialize: unary((request) => {
    if (run) throw new Refusal(status.FAILED_PRECONDITION, `participant '${NAME}' is in another run; a participant serves one run at a time`);
    const secret = request.run_secret;
    if (secret.length < 16 || secret.length > 256) {
      throw new Refusal(status.INVALID_ARGUMENT, `run_secret must be 16 to 256 random bytes, got ${secret.length}`);
    }
    const lease = request.lease_seconds;
    if (lease !== 0 && !(lease > 0 && lease <= MAX_LEASE)) {
      throw new Refusal(status.INVALID_ARGUMENT, `lease_seconds must be a number of seconds > 0 and <= ${MAX_LEASE} (24 h), got ${lease}`);
    }
    finite('start_time', request.start_time);
    finite('step_size', request.step_size);
    if (request.stop_time !== undefined && request.stop_time !== null) finite('stop_time', request.stop_time);
    const parameters = values(request.parameters, 'CAUSALITY_PARAMETER');
    const inputs = values(request.inputs, 'CAUSALITY_INPUT');
    run = {
      id: request.run_id,
      secret: Buffer.from(secret),
      lease: lease || DEFAULT_LEASE,
      reached: request.start_time,
      intrusion: null,
      intrusions: 0,
      timer: null,
      gain: parameters.gain ?? 2,
      u: inputs.u ?? 0,
      steps: 0,
    };
    touch(run);
    log('run_initialized', { run_id: run.id, lease_s: run.lease });
    return { outputs: outputs() };
  }),

  DoStep: unary(step),

  StepStream(call) {
    let carried = null; // the run whose owner this stream is
    let refused = false;
    call.on('data', (request) => {
      if (refused) return;
      try {
        if (run && request.run_id === run.id && sameSecret(request.run_secret, run.secret)) carried = run;
        call.write(step(request, call.getPeer()));
      } catch (error) {
        if (!(error instanceof Refusal)) throw error;
        refused = true;
        call.emit('error', { code: error.code, details: error.details }); // ends the stream
      }
    });
    const over = () => {
      if (carried && carried === run) endRun('its step stream ended without Terminate');
    };
    call.on('end', () => {
      over();
      call.end();
    });
    call.on('close', over);
    call.on('cancelled', over);
  },

  Terminate: unary((request, peer) => {
    if (!run) return {}; // a run that has already ended: Terminate is idempotent
    const active = ofTheRun(request, 'Terminate', peer);
    endRun(request.reason || 'terminated');
    if (active.intrusion) throw new Refusal(status.ABORTED, refusal(active));
    return {};
  }),
};

const server = new grpc.Server();
server.addService(pb.GRPCComponentService.service, service);
const health = new HealthImplementation({ '': 'NOT_SERVING', 'coupler.v1.GRPCComponentService': 'NOT_SERVING' });
health.addToServer(server);
server.bindAsync(`127.0.0.1:${option('--port', '0')}`, grpc.ServerCredentials.createInsecure(), (error, port) => {
  if (error) {
    console.error(`participant-node: cannot listen: ${error.message}`);
    process.exit(1);
  }
  health.setStatus('', 'SERVING');
  health.setStatus('coupler.v1.GRPCComponentService', 'SERVING');
  console.log(`serving ${NAME} at grpc://127.0.0.1:${port}`);
});
for (const signal of ['SIGTERM', 'SIGINT']) {
  process.on(signal, () => server.tryShutdown(() => process.exit(0)));
}
