import { z } from 'zod/mini';
import { LinkError } from '../../fleet/errors';
import type { VendorErrorParser } from '../../fleet/http';
import { preprocess } from '../../fleet/schema';

/**
 * Wire format of the xTool D-series (D1, D1 Pro, D1 Pro 2.0): HTTP on :8080, WebSocket on :8081.
 * Source: ../shared/protocols/xtool-d-series-api.txt ("the document") and the captures in
 * tests/fixtures/xtool (SOURCES.md). Every schema is lenient where the firmware is sloppy:
 *
 * - numbers may arrive as strings (`"progress":"0"`, `"working":"0"`): `num` accepts both;
 * - unknown keys pass through (`z.looseObject`);
 * - enum-like values the document does not know map to an explicit `unknown` with the raw value;
 * - failures come as `{"result":"fail"}` with HTTP 200, unknown paths as `{"result":"no file"}`:
 *   `parseXtoolError` turns any `result` other than "ok" into a `vendor` LinkError;
 * - JSON may come without a JSON content type: HttpClient.json parses whatever the type.
 */

/** A number, or a string holding one ("0", " 12.5 "). Empty strings and garbage fail. */
export const num = preprocess(
  (v) => (typeof v === 'string' && v.trim() !== '' ? Number(v.trim()) : v),
  z.number(),
);

/** A string, or a number the firmware sent unquoted. */
export const str = z.pipe(
  z.union([z.string(), z.number()]),
  z.transform((v) => String(v)),
);

/** 1 = on, 0 = off (document, /peripherystatus and /system?action=set*StopSwitch). */
export const flag = z.pipe(
  num,
  z.transform((n) => n !== 0),
);

/** Most answers carry `result`; the vendor parser already rejected anything but "ok". */
const result = z.optional(z.string());

// ---------------------------------------------------------------------------------------------
// HTTP answers

/** GET /ping → {"result":"ok"} */
export const pingSchema = z.looseObject({ result });

/**
 * GET /progress → {"progress":100.00,"working":56197,"line":0}. `progress` is percent of the
 * current (or last) job, `working` milliseconds since it started, `line` the current G-code line.
 * Real devices send all three as strings at times ("progress":"0").
 */
export const progressSchema = z.looseObject({
  progress: num,
  working: num,
  line: z.optional(num),
});
export type Progress = z.output<typeof progressSchema>;

/** GET /getmachinetype → {"result":"ok","type":"xTool D1Pro"} */
export const machineTypeSchema = z.looseObject({ result, type: str });

/** GET /getlaserpowertype → {"result":"ok","power":10} (watts) */
export const laserPowerTypeSchema = z.looseObject({ result, power: num });

/** GET /getlaserpowerinfo → {"result":"ok","type":0,"power":10}; `type` meaning unknown (document). */
export const laserPowerInfoSchema = z.looseObject({ result, type: z.optional(num), power: num });

export type FlameSensitivity = 'high' | 'low' | 'off' | `unknown (raw ${number})`;

/** 1 = high, 2 = low, 3 = off (document; the S1 uses another scale, see state-vocabularies.json). */
export function flameSensitivityWords(n: number): FlameSensitivity {
  switch (n) {
    case 1:
      return 'high';
    case 2:
      return 'low';
    case 3:
      return 'off';
    default:
      return `unknown (raw ${n})`;
  }
}

/**
 * GET /peripherystatus. Older firmware answers only `result`, `status` and `sdCard`, so every
 * setting is optional (the views say "not reported by this firmware").
 */
export const peripheryStatusSchema = z.looseObject({
  result,
  status: z.optional(str),
  sdCard: z.optional(flag),
  limitStopFlag: z.optional(flag),
  tiltStopFlag: z.optional(flag),
  movingStopFlag: z.optional(flag),
  tiltThreshold: z.optional(num),
  movingThreshold: z.optional(num),
  flameAlarmMode: z.optional(num),
  flameAlarmSensitivity: z.optional(num),
});
export type PeripheryStatus = z.output<typeof peripheryStatusSchema>;

/** GET /system?action=mac */
export const macSchema = z.looseObject({ result, mac: str });

/** GET /system?action=version → {"sn":"…","version":"V40.31.006.01 B2"} */
export const versionSchema = z.looseObject({ result, sn: z.optional(str), version: str });

export type WorkingCode = 'idle' | 'api' | 'button' | 'unknown';

export interface WorkingSta {
  /**
   * "0" idle, "1" running a job started through the API (/read), "2" running a job started with
   * the machine's button — also "file loaded, waiting for the button" (the two look the same).
   */
  code: WorkingCode;
  raw: string;
}

export function workingCode(raw: string): WorkingCode {
  switch (raw.trim()) {
    case '0':
      return 'idle';
    case '1':
      return 'api';
    case '2':
      return 'button';
    default:
      return 'unknown';
  }
}

/** GET /system?action=get_working_sta → {"result":"ok","working":"0"} (a string on real devices). */
export const workingStaSchema = z.pipe(
  z.looseObject({ result, working: str }),
  z.transform((v): WorkingSta => ({ code: workingCode(v.working), raw: v.working })),
);

/** GET /system?action=offset → red-cross offset {"x":0.0,"y":0.0} (mm). */
export const offsetSchema = z.looseObject({ result, x: num, y: num });

/** GET /system?action=dotMode → {"dotMode":0} */
export const dotModeSchema = z.looseObject({ result, dotMode: num });

/** GET /system?action=get_dev_name → {"name":"My xTool D1 Pro"} */
export const devNameSchema = z.looseObject({ result, name: str });

/** Answers that only say ok (set*, /cmd, /read, /delete, /cnc/data, /upload). */
export const resultSchema = z.looseObject({ result: z.string() });

/**
 * GET /list?dir= → {"type":"dir","name":["/frame.gcode","/tmp.gcode"]}. An empty directory may
 * come without `name` (treated as []), a single entry as a bare string.
 */
export const listSchema = z.looseObject({
  type: z.optional(str),
  name: z.pipe(
    z.optional(z.union([z.array(str), str])),
    z.transform((v) => (v === undefined ? [] : Array.isArray(v) ? v : [v])),
  ),
});
export type FileList = z.output<typeof listSchema>;

/** POST /upgrade answers "OK" or "FAIL" in plain text (document); anything else is unknown. */
export const upgradeReplySchema = z.pipe(
  z.pipe(
    z.string(),
    z.transform((t) => t.trim().toUpperCase()),
  ),
  z.enum(['OK', 'FAIL']),
);

/**
 * The vendor error parser for HttpClient: `{"result":"fail"}` (HTTP 200) and friends become a
 * `vendor` LinkError; bodies without `result` (/progress, /list) pass.
 */
export const parseXtoolError: VendorErrorParser = (status, body) => {
  if (typeof body !== 'object' || body === null || !('result' in body)) return null;
  const r = (body as { result: unknown }).result;
  if (typeof r !== 'string' || r.trim().toLowerCase() === 'ok') return null;
  const word = r.trim();
  const message =
    word === 'no file'
      ? 'The laser does not know this path or file (it answered "no file")'
      : word === 'fail'
        ? 'The laser refused (it answered "fail")'
        : `The laser answered "${word}"`;
  return new LinkError('vendor', message, { status, vendorMessage: word });
};

// ---------------------------------------------------------------------------------------------
// WebSocket frames (ws://<ip>:8081/, read-only status channel; see ws-frames.json)

export type FrameState =
  'idle' | 'running-online' | 'job-loaded' | 'running-offline' | 'framing' | 'frame-ready' | 'paused';

export type Sensor = 'tilt' | 'moving' | 'limit' | 'flame';

export type XtoolFrame =
  | { kind: 'state'; state: FrameState; raw: string }
  | { kind: 'stopped'; raw: string }
  | { kind: 'error'; raw: string }
  | { kind: 'sensor'; sensor: Sensor; raw: string }
  | { kind: 'unknown'; raw: string };

const STATE_FRAMES: Record<string, FrameState> = {
  'ok:IDLE': 'idle',
  'ok:WORKING_ONLINE': 'running-online',
  'ok:WORKING_ONLINE_READY': 'job-loaded',
  'ok:WORKING_OFFLINE': 'running-offline',
  'ok:WORKING_FRAMING': 'framing',
  'ok:WORKING_FRAME_READY': 'frame-ready',
  'ok:PAUSING': 'paused',
};

const SENSOR_FRAMES: Record<string, Sensor> = {
  'err:tiltCheck': 'tilt',
  'err:movingCheck': 'moving',
  'err:limitCheck': 'limit',
  'err:flameCheck': 'flame',
};

/**
 * Frames end with a terminator character (xTool-Connect drops the last character, ha-xtool
 * strips whitespace): trailing whitespace and control characters are removed before matching.
 * The stop frame is spelled WORK_STOPPED in the document and WORK_STOPED by xTool's own code.
 */
export function parseFrameText(data: string): XtoolFrame {
  // eslint-disable-next-line no-control-regex
  const raw = data.replace(/[\s\u0000-\u001f]+$/, '').replace(/^\s+/, '');
  const state = STATE_FRAMES[raw];
  if (state) return { kind: 'state', state, raw };
  if (
    raw === 'WORK_STOPPED' ||
    raw === 'WORK_STOPED' ||
    raw === 'ok:WORK_STOPPED' ||
    raw === 'ok:WORK_STOPED'
  ) {
    return { kind: 'stopped', raw };
  }
  if (raw === 'ok:ERROR') return { kind: 'error', raw };
  const sensor = SENSOR_FRAMES[raw];
  if (sensor) return { kind: 'sensor', sensor, raw };
  return { kind: 'unknown', raw };
}

export const frameSchema = z.pipe(z.string(), z.transform(parseFrameText));

// ---------------------------------------------------------------------------------------------
// Models: other xTool families speak other protocols (S1, F1, P2, M1, MetalFab…)

export type ModelFamily = 'd-series' | 'unsupported';

/** "xTool D1Pro", "xTool D1", "xTool D1 Pro 2.0" are D-series; anything else is not ours. */
export function classifyMachineType(type: string): ModelFamily {
  return /\bD1/i.test(type) || /xTool_?D1/i.test(type) ? 'd-series' : 'unsupported';
}

// ---------------------------------------------------------------------------------------------
// Discovery (the gateway's GET /api/discover/xtool; the device's UDP reply inside)

/** The device's reply: {"requestId":123456,"ip":"…","name":"xTool D1 Pro","version":"40.31.006.01"}. */
export const discoveryReplySchema = z.looseObject({
  requestId: z.optional(num),
  ip: z.string(),
  name: z.pipe(
    z.optional(str),
    z.transform((v) => v ?? ''),
  ),
  version: z.pipe(
    z.optional(str),
    z.transform((v) => v ?? ''),
  ),
  via: z.pipe(
    z.optional(z.string()),
    z.transform((v) => (v === 'udp' || v === 'tcp' ? v : v === undefined ? 'unknown' : `unknown (raw ${v})`)),
  ),
});
export type DiscoveryReply = z.output<typeof discoveryReplySchema>;

export const discoveryResponseSchema = z.looseObject({
  replies: z.array(discoveryReplySchema),
  broadcast: z.optional(z.string()),
  /** Problems the gateway met (a broadcast it could not send). */
  warnings: z.optional(z.array(z.string())),
});
export type DiscoveryResponse = z.output<typeof discoveryResponseSchema>;
