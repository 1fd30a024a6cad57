import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { z } from 'zod';
import { families } from '../src/controllers/families';
import type { GatewaySecrets } from '../src/fleet/contract';
import { kindsAccepting } from '../src/fleet/server-part';
import {
  MACHINE_APIS,
  MACHINE_ID,
  type MachineApi,
  type MachineInfo,
  type MachineKind,
} from '../src/fleet/types';
import { patternsOfForms, redactText, secretTextForms } from './redact';

/**
 * The machines file (DESIGN.md, "The machines file"): `SHOPDECK_MACHINES`, else
 * `machines.json` in the project root, else the built-in demo fleet. A bad file stops the
 * server with a message that names the file, the entry (index and id) and the field.
 */

export interface MachineEntry {
  id: string;
  name: string;
  kind: MachineKind;
  simulated: boolean;
  /** Controller base URL (null for simulated machines without one). */
  url: URL | null;
  /** WebSocket base URL when the socket is elsewhere. */
  wsUrl: URL | null;
  /** Resolved secret values (never sent to the browser). */
  secrets: GatewaySecrets;
  /**
   * SHA-256 fingerprint of the controller's TLS certificate (DER), normalised as Node's
   * `cert.fingerprint256` ("AB:CD:…", uppercase). When set, the gateway talks to the
   * controller's `https:`/`wss:` addresses only if they show this certificate; when absent it
   * trusts the first certificate it sees and pins it (`tls-pin.ts`).
   */
  tlsFingerprint?: string;
  /** Where the machine stands (a bay, a room): the fleet page groups by it. */
  group?: string;
  /**
   * A board on a USB serial port (issue 19; a family whose `machineFields` has `serial`): the
   * gateway owns the port and its family's server part serves the family's API from it
   * (`server.serial`, src/fleet/server-part.ts). `path` is a device or "auto".
   */
  serial?: { path: string; baudRate: number };
  /** Families that speak more than one API (their `machineFields` has `api`): force the API (`dsf` or `standalone`); absent, the gateway probes (DWC's order). */
  api?: MachineApi;
}

export interface MachinesConfig {
  /** Absolute path of the file, or null for the built-in demo fleet. */
  file: string | null;
  machines: MachineEntry[];
}

export class MachinesFileError extends Error {
  constructor(
    readonly file: string,
    readonly problems: string[],
  ) {
    super(`Shopdeck: the machines file ${file} is not valid:\n  ${problems.join('\n  ')}`);
    this.name = 'MachinesFileError';
  }
}

/** The built-in demo fleet: each family's `demo` machines (src/controllers/<kind>/family.ts). */
export const DEMO_FLEET: ReadonlyArray<{ id: string; name: string; kind: MachineKind; api?: MachineApi }> =
  Object.values(families).flatMap((f) =>
    (f.demo ?? []).map((d) => ({ id: d.id, name: d.name, kind: f.kind, ...(d.api ? { api: d.api } : {}) })),
  );

/** Control and format characters, line and paragraph separators: not printable in a group name. */
const UNPRINTABLE = /[\p{Cc}\p{Cf}\p{Zl}\p{Zp}]/u;

/** The kinds the machines file accepts: the families' (src/controllers/families.ts). */
const MACHINE_KINDS = Object.keys(families) as [MachineKind, ...MachineKind[]];

const entrySchema = z.strictObject({
  id: z.string({ error: 'missing or not a string' }).regex(MACHINE_ID, 'must be 1 to 40 of a-z, 0-9 and "-"'),
  name: z
    .string({ error: 'missing or not a string' })
    .trim()
    .min(1, 'must not be empty')
    .max(120, 'too long'),
  kind: z.enum(MACHINE_KINDS, { error: `must be one of ${MACHINE_KINDS.join(', ')}` }),
  url: z.string({ error: 'must be a string' }).optional(),
  wsUrl: z.string({ error: 'must be a string' }).optional(),
  apiKey: z.string({ error: 'must be a string' }).min(1, 'must not be empty').optional(),
  password: z.string({ error: 'must be a string' }).min(1, 'must not be empty').optional(),
  simulated: z.boolean({ error: 'must be true or false' }).optional(),
  tlsFingerprint: z.string({ error: 'must be a string' }).optional(),
  serial: z
    .string({ error: 'must be a string' })
    .trim()
    .min(1, 'must not be empty')
    .max(200, 'too long')
    .refine((v) => !UNPRINTABLE.test(v), 'must be printable text (no control characters)')
    .optional(),
  baudRate: z
    .number({ error: 'must be a number' })
    .int('must be a whole number')
    .min(300, 'must be at least 300')
    .max(4_000_000, 'must be at most 4000000')
    .optional(),
  api: z.enum(MACHINE_APIS, { error: `must be one of ${MACHINE_APIS.join(', ')}` }).optional(),
  group: z
    .string({ error: 'must be a string' })
    .trim()
    .min(1, 'must not be empty')
    .max(60, 'too long (at most 60 characters)')
    .refine((v) => !UNPRINTABLE.test(v), 'must be printable text (no control characters or line breaks)')
    .optional(),
});

const FINGERPRINT_COLONS = /^[0-9a-f]{2}(:[0-9a-f]{2}){31}$/i;
const FINGERPRINT_BARE = /^[0-9a-f]{64}$/i;

/**
 * A SHA-256 certificate fingerprint in the form Node's `cert.fingerprint256` has ("AB:CD:…",
 * uppercase, 32 colon-separated pairs). Accepts 64 hex digits with or without colons, any
 * case, surrounding spaces ignored (what `openssl x509 -noout -fingerprint -sha256` prints
 * after the "="). Null when it is not one.
 */
export function normalizeFingerprint(value: string): string | null {
  const v = value.trim();
  if (!FINGERPRINT_COLONS.test(v) && !FINGERPRINT_BARE.test(v)) return null;
  const hex = v.replace(/:/g, '').toUpperCase();
  return hex.match(/../g)?.join(':') ?? null;
}

function describeEntry(index: number, raw: unknown): string {
  const id = raw && typeof raw === 'object' && 'id' in raw ? (raw as { id: unknown }).id : undefined;
  return `machines[${index}]${typeof id === 'string' ? ` (id "${id}")` : ''}`;
}

function parseUrl(value: string, protocols: string[]): URL | string {
  let u: URL;
  try {
    u = new URL(value);
  } catch {
    return `"${value}" is not a URL`;
  }
  if (!protocols.includes(u.protocol))
    return `"${value}" must start with ${protocols.map((p) => p + '//').join(' or ')}`;
  if (u.search || u.hash) return `"${value}" must not have a query or fragment`;
  return u;
}

function resolveSecret(
  value: string | undefined,
  env: NodeJS.ProcessEnv,
): string | undefined | { missing: string } {
  if (value === undefined) return undefined;
  if (!value.startsWith('env:')) return value;
  const name = value.slice(4);
  const v = env[name];
  if (v === undefined || v === '') return { missing: name };
  return v;
}

/** Kinds whose boards the gateway can drive over a serial port (their family's `machineFields`). */
const SERIAL_KINDS: ReadonlySet<MachineKind> = new Set(kindsAccepting(families, 'serial'));
/** Kinds whose API the machines file may force (`api`). */
const API_KINDS: ReadonlySet<MachineKind> = new Set(kindsAccepting(families, 'api'));

/** "a" · "a or b" · "a, b or c". */
function either(words: readonly string[]): string {
  return words.length < 2
    ? (words[0] ?? '')
    : `${words.slice(0, -1).join(', ')} or ${words[words.length - 1]}`;
}
export const DEFAULT_BAUD_RATE = 115_200;

/** A device path: /dev/…, COM<n>, \\.\COM<n>, or "auto". */
const SERIAL_PATH = /^(auto|\/dev\/[A-Za-z0-9._/+-]+|COM[0-9]{1,3}|\\\\\.\\COM[0-9]{1,3})$/;

/** The `serial` and `baudRate` fields of an entry (problems pushed, null when none or wrong). */
function serialOf(
  e: z.infer<typeof entrySchema>,
  where: string,
  simulated: boolean,
  problems: string[],
): { path: string; baudRate: number } | null {
  if (e.serial === undefined) {
    if (e.baudRate !== undefined) problems.push(`${where}: field "baudRate": only used with "serial"`);
    return null;
  }
  const before = problems.length;
  if (!SERIAL_KINDS.has(e.kind))
    problems.push(
      `${where}: field "serial": only ${either([...SERIAL_KINDS])} boards can be reached over a serial port`,
    );
  else if (simulated)
    problems.push(
      `${where}: field "serial": a simulated machine has no port (remove "serial" or "simulated")`,
    );
  else if (!SERIAL_PATH.test(e.serial) || e.serial.includes('..'))
    problems.push(
      `${where}: field "serial": "${e.serial}" must be a device such as /dev/ttyACM0 or COM3, or "auto"`,
    );
  if (e.wsUrl !== undefined) problems.push(`${where}: field "wsUrl": not used with "serial"`);
  if (problems.length > before) return null;
  return { path: e.serial, baudRate: e.baudRate ?? DEFAULT_BAUD_RATE };
}

/** Validates the parsed JSON of a machines file. Throws MachinesFileError listing every problem. */
export function parseMachines(file: string, data: unknown, env: NodeJS.ProcessEnv): MachineEntry[] {
  const problems: string[] = [];
  if (!data || typeof data !== 'object' || Array.isArray(data) || !('machines' in data)) {
    throw new MachinesFileError(file, [
      'top level: field "machines": missing (expected { "machines": [ … ] })',
    ]);
  }
  const list = (data as { machines: unknown }).machines;
  if (!Array.isArray(list))
    throw new MachinesFileError(file, ['top level: field "machines": must be an array']);
  const extra = Object.keys(data).filter((k) => k !== 'machines' && k !== '$schema' && k !== 'comment');
  if (extra.length) problems.push(`top level: field "${extra.join('", "')}": unknown field`);
  const out: MachineEntry[] = [];
  const seen = new Map<string, number>();
  list.forEach((raw, i) => {
    const where = describeEntry(i, raw);
    const r = entrySchema.safeParse(raw);
    if (!r.success) {
      for (const issue of r.error.issues) {
        if (issue.code === 'unrecognized_keys') {
          problems.push(`${where}: field "${issue.keys.join('", "')}": unknown field`);
        } else if (issue.path.length === 0) {
          problems.push(`${where}: must be an object with id, name, kind and url`);
        } else {
          problems.push(`${where}: field "${issue.path.join('.')}": ${issue.message}`);
        }
      }
      return;
    }
    const e = r.data;
    const before = seen.get(e.id);
    if (before !== undefined) {
      problems.push(`${where}: field "id": duplicate id "${e.id}" (also machines[${before}])`);
      return;
    }
    seen.set(e.id, i);
    const simulated = e.simulated ?? false;
    let url: URL | null = null;
    let wsUrl: URL | null = null;
    const serial = serialOf(e, where, simulated, problems);
    if (e.url === undefined) {
      if (!simulated && e.serial === undefined)
        problems.push(
          `${where}: field "url": missing (required unless "simulated": true${SERIAL_KINDS.has(e.kind) ? ', or "serial" for a board on USB' : ''})`,
        );
    } else if (e.serial !== undefined) {
      problems.push(`${where}: field "serial": use either "url" or "serial", not both`);
    } else {
      const u = parseUrl(e.url, ['http:', 'https:']);
      if (typeof u === 'string') problems.push(`${where}: field "url": ${u}`);
      else url = u;
    }
    if (e.wsUrl !== undefined) {
      const u = parseUrl(e.wsUrl, ['ws:', 'wss:']);
      if (typeof u === 'string') problems.push(`${where}: field "wsUrl": ${u}`);
      else wsUrl = u;
    }
    let tlsFingerprint: string | undefined;
    if (e.tlsFingerprint !== undefined) {
      const fp = normalizeFingerprint(e.tlsFingerprint);
      // Only TLS connections have a certificate: a fingerprint on a plain http:// machine
      // would look like protection while the traffic (and the secrets) go in clear.
      const tlsAddress = url?.protocol === 'https:' || wsUrl?.protocol === 'wss:';
      // A url that is already reported as wrong says nothing about TLS.
      const badAddress = (e.url !== undefined && !url) || (e.wsUrl !== undefined && !wsUrl);
      if (fp === null) {
        problems.push(
          `${where}: field "tlsFingerprint": must be the SHA-256 fingerprint of the controller's certificate, 64 hex digits with or without colons ("AB:CD:…")`,
        );
      } else if (!tlsAddress && !badAddress) {
        problems.push(
          `${where}: field "tlsFingerprint": only used for https:// and wss:// addresses, and this machine has none (use an https:// url, or remove the field)`,
        );
      } else {
        tlsFingerprint = fp;
      }
    }
    if (e.api !== undefined && !API_KINDS.has(e.kind))
      problems.push(
        `${where}: field "api": only for ${either([...API_KINDS].map((k) => `"kind": "${k}"`))} (${either(MACHINE_APIS)})`,
      );
    const secrets: GatewaySecrets = {};
    for (const field of ['apiKey', 'password'] as const) {
      const v = resolveSecret(e[field], env);
      if (v === undefined) continue;
      if (typeof v === 'object')
        problems.push(`${where}: field "${field}": environment variable ${v.missing} is not set`);
      else secrets[field] = v;
    }
    out.push({
      id: e.id,
      name: e.name,
      kind: e.kind,
      simulated,
      url,
      wsUrl,
      secrets,
      ...(tlsFingerprint ? { tlsFingerprint } : {}),
      ...(e.group !== undefined ? { group: e.group } : {}),
      ...(serial ? { serial } : {}),
      ...(e.api !== undefined ? { api: e.api } : {}),
    });
  });
  if (problems.length) throw new MachinesFileError(file, problems);
  return out;
}

export function demoFleet(): MachineEntry[] {
  return DEMO_FLEET.map((m) => ({ ...m, simulated: true, url: null, wsUrl: null, secrets: {} }));
}

/** Finds and loads the machines file. Throws MachinesFileError when it is wrong. */
export function loadMachines(
  opts: { machinesFile?: string; env?: NodeJS.ProcessEnv; cwd?: string } = {},
): MachinesConfig {
  const env = opts.env ?? process.env;
  const cwd = opts.cwd ?? process.cwd();
  const explicit = opts.machinesFile ?? env.SHOPDECK_MACHINES;
  let file: string | null = null;
  if (explicit) {
    file = path.resolve(cwd, explicit);
    if (!existsSync(file))
      throw new MachinesFileError(file, ['the file does not exist (set by SHOPDECK_MACHINES)']);
  } else if (existsSync(path.join(cwd, 'machines.json'))) {
    file = path.join(cwd, 'machines.json');
  }
  if (!file) return { file: null, machines: demoFleet() };
  let data: unknown;
  try {
    data = JSON.parse(readFileSync(file, 'utf8')) as unknown;
  } catch (e) {
    throw new MachinesFileError(file, [`not readable JSON: ${e instanceof Error ? e.message : String(e)}`]);
  }
  return { file, machines: parseMachines(file, data, env) };
}

export function machineInfo(m: MachineEntry): MachineInfo {
  return {
    id: m.id,
    name: m.name,
    kind: m.kind,
    simulated: m.simulated,
    ...(m.group !== undefined ? { group: m.group } : {}),
  };
}

/**
 * Every secret value of a machine, in the text forms it could be echoed back in (longest first):
 * the forms of `secretPatterns` (redact.ts) that are valid UTF-8. Secrets shorter than 4 are left out.
 */
export function secretForms(secrets: GatewaySecrets): string[] {
  return secretTextForms(secrets);
}

/** Replaces each form in `text` by `[redacted]` (redact.ts `redactText`; keep and reuse `forms`). */
export function redact(text: string, forms: readonly string[]): string {
  return redactText(text, patternsOfForms(forms));
}
