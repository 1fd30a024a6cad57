import { z } from 'zod/mini';
import type { Faults } from './sim';

/**
 * The Simulator tab of a simulated machine, described as data. The simulators run in the gateway
 * (one world for every tab); `GET /api/sim/<id>` (gateway/sim-api.ts) answers the controls with
 * their current values and `POST /api/sim/<id>` sets one, and the page renders what it is told.
 * No simulator code here: the browser imports this file, and the production bundle carries no
 * simulator.
 *
 * Groups:
 * - `world`: the family simulator's stand-ins for the physical world (`Simulator.controls()`:
 *   the machine's button, a flame under the laser), buttons;
 * - `faults`: fault injection of `FaultySimulator` (src/fleet/sim.ts);
 * - `simulator`: the simulator itself (`reset`: a fresh world, no faults).
 */

export const SIM_GROUPS = ['world', 'faults', 'simulator'] as const;
export type SimGroup = (typeof SIM_GROUPS)[number];

const base = { group: z.enum(SIM_GROUPS), id: z.string(), label: z.string() };

export const simControlSchema = z.discriminatedUnion('type', [
  /** A button: runs once. */
  z.object({ ...base, type: z.literal('action') }),
  /** On or off. */
  z.object({ ...base, type: z.literal('toggle'), value: z.boolean() }),
  /** One of a few numbers. */
  z.object({
    ...base,
    type: z.literal('choice'),
    value: z.number(),
    choices: z.array(z.number()),
    unit: z.optional(z.string()),
  }),
]);
export type SimControlView = z.infer<typeof simControlSchema>;

/** `GET /api/sim/<id>`, and the answer of every `POST`. */
export const simPanelSchema = z.object({
  machine: z.string(),
  kind: z.string(),
  controls: z.array(simControlSchema),
});
export type SimPanel = z.infer<typeof simPanelSchema>;

/** `POST /api/sim/<id>`: one control; `value` for a toggle (boolean) or a choice (number). */
export const simSetSchema = z.strictObject({
  group: z.enum(SIM_GROUPS),
  id: z.string().check(z.minLength(1), z.maxLength(100)),
  value: z.optional(z.union([z.boolean(), z.number()])),
});
export type SimSet = z.infer<typeof simSetSchema>;

type FaultToggle = { [K in keyof Faults]: Faults[K] extends boolean ? K : never }[keyof Faults];

/** The fault injection controls, in the order the tab shows them. */
export const FAULT_CONTROLS: ReadonlyArray<
  | { id: FaultToggle; type: 'toggle'; label: string }
  | { id: 'latencyMs'; type: 'choice'; label: string; choices: readonly number[]; unit: string }
  | { id: 'closeSockets'; type: 'action'; label: string }
> = [
  { id: 'drop', type: 'toggle', label: 'Drop connections' },
  { id: 'http5xx', type: 'toggle', label: 'Answer 503' },
  { id: 'malformed', type: 'toggle', label: 'Malformed bodies' },
  { id: 'latencyMs', type: 'choice', label: 'Latency', choices: [0, 200, 1000, 3000, 10000], unit: 'ms' },
  { id: 'closeSockets', type: 'action', label: 'Close sockets' },
];

/** Throws the simulator's world away and starts a fresh one without faults. */
export const SIM_RESET = {
  group: 'simulator',
  id: 'reset',
  type: 'action',
  label: 'Restart the simulator (a fresh world, no faults)',
} as const satisfies SimControlView;
