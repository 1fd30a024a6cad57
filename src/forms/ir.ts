/**
 * The form engine's intermediate representation (IR): a flat table of nodes, each with a stable
 * string id, built by a controller family from whatever schema its controller sends. The engine
 * (model, validation, renderer) knows nothing about any controller.
 *
 * Values: every value-bearing node (leaves and variants) has one value in the model, keyed by id.
 * Numbers being typed are kept as text until they parse, so a half-typed "1e" survives a reload.
 */

export interface RatioValue {
  numerator: number | string;
  denominator: number | string;
}

export type FormValue = boolean | number | string | RatioValue;

/** Show a node only when the field `field` currently has one of `values`. */
export interface PresentWhen {
  field: string;
  values: readonly FormValue[];
}

interface NodeBase {
  id: string;
  /** Last segment: what the label shows. */
  key: string;
  label: string;
  /** Controller-supplied HTML: always sanitized before it reaches the DOM. */
  description: string;
  /** Plain text of the description, for search. */
  searchText: string;
  parent: string | null;
  experimental?: boolean;
  presentWhen?: PresentWhen;
}

export interface BooleanNode extends NodeBase {
  kind: 'boolean';
  default?: boolean;
}
export interface DiscreteNode extends NodeBase {
  kind: 'discrete';
  options: readonly string[];
  default?: string;
}
export interface NumberNode extends NodeBase {
  kind: 'integer' | 'float';
  min: number;
  max: number;
  unit: string;
  default?: number;
}
export interface RatioNode extends NodeBase {
  kind: 'ratio';
  /** Limits apply to numerator / denominator. */
  min: number;
  max: number;
  default?: { numerator: number; denominator: number };
}
export interface StringNode extends NodeBase {
  kind: 'string';
  default?: string;
}
export interface GroupNode extends NodeBase {
  kind: 'group';
  /** Hint: show the children as tabs. */
  tabbed: boolean;
  children: readonly string[];
}
export interface VariantNode extends NodeBase {
  kind: 'variant';
  /** Child ids; the value of a variant is the `key` of the selected child. */
  children: readonly string[];
  default?: string;
}
/** A kind the engine does not know: shown read-only with its raw kind. */
export interface UnknownNode extends NodeBase {
  kind: 'unknown';
  rawKind: string;
}

export type FormNode =
  BooleanNode | DiscreteNode | NumberNode | RatioNode | StringNode | GroupNode | VariantNode | UnknownNode;

export type ValueNode = BooleanNode | DiscreteNode | NumberNode | RatioNode | StringNode | VariantNode;

export interface FormSchema {
  nodes: ReadonlyMap<string, FormNode>;
  /** Top-level sections, in controller order. */
  roots: readonly string[];
  /** Identity of the schema (drafts are kept per schema key). */
  key: string;
}

export function isValueNode(n: FormNode): n is ValueNode {
  return n.kind !== 'group' && n.kind !== 'unknown';
}

/** |limit| at or beyond this means "no limit" (Prunt sends ±1E100). */
export const NO_LIMIT = 1e99;

function lowText(min: number): string | null {
  if (!Number.isFinite(min) || min <= -NO_LIMIT) return null;
  // Prunt's "must be positive" limit is 1E-100: say "> 0" rather than print it.
  if (min > 0 && min < 1e-50) return '> 0';
  return `≥ ${fmtLimit(min)}`;
}

function highText(max: number): string | null {
  if (!Number.isFinite(max) || max >= NO_LIMIT) return null;
  return `≤ ${fmtLimit(max)}`;
}

function fmtLimit(n: number): string {
  return Number.isInteger(n) ? String(n) : String(Number(n.toPrecision(12)));
}

/** "≥ 0.125 · ≤ 3 amp", "> 0 · no upper limit", "no limit". */
export function rangeText(min: number, max: number, unit = ''): string {
  const lo = lowText(min);
  const hi = highText(max);
  if (!lo && !hi) return 'no limit';
  const u = unit ? ` ${unit}` : '';
  return `${lo ?? 'no lower limit'} · ${hi ? `${hi}${u}` : 'no upper limit'}`;
}

export function valuesEqual(a: FormValue | undefined, b: FormValue | undefined): boolean {
  if (a === b) return true;
  if (a === undefined || b === undefined) return false;
  if (typeof a === 'object' && typeof b === 'object') {
    return numEq(a.numerator, b.numerator) && numEq(a.denominator, b.denominator);
  }
  if (typeof a === 'object' || typeof b === 'object') return false;
  // A number being typed is text: compare it with the number it stands for.
  if (typeof a !== typeof b && (typeof a === 'number' || typeof b === 'number')) {
    if (typeof a === 'boolean' || typeof b === 'boolean') return false;
    return numEq(a, b);
  }
  return false;
}

/** Parse a number the user typed (or a number): NaN when it is not one. */
/**
 * A value at Prunt's "no limit" (±1E100) in words: "no limit", "no limit (negative)"; null for
 * any other number. The form shows these words in the field, and `toNumber` reads them back.
 */
export function noLimitText(n: number): string | null {
  if (!Number.isFinite(n) || Math.abs(n) < NO_LIMIT) return null;
  return n > 0 ? 'no limit' : 'no limit (negative)';
}

const NO_LIMIT_WORDS = /^(-|−)?\s*no limit(\s*\(negative\))?$/i;

export function toNumber(v: number | string): number {
  if (typeof v === 'number') return v;
  const t = v.trim();
  if (t === '') return NaN;
  const words = NO_LIMIT_WORDS.exec(t);
  if (words) return words[1] || words[2] ? -1e100 : 1e100;
  return Number(t);
}

function numEq(a: number | string, b: number | string): boolean {
  if (a === b) return true;
  const x = toNumber(a);
  const y = toNumber(b);
  return Number.isFinite(x) && x === y;
}

/** Ancestors of a node, nearest first. */
export function ancestors(schema: FormSchema, id: string): string[] {
  const out: string[] = [];
  let p = schema.nodes.get(id)?.parent ?? null;
  while (p !== null) {
    out.push(p);
    p = schema.nodes.get(p)?.parent ?? null;
  }
  return out;
}

/** Display breadcrumb "Steppers › STEPPER_1 › Run current". */
export function breadcrumb(schema: FormSchema, id: string): string {
  const parts = [id, ...ancestors(schema, id)].reverse().map((i) => schema.nodes.get(i)?.label ?? i);
  // "Fans › Fans › FAN_1" (a module holding a group of its own name) reads as "Fans › FAN_1".
  return parts.filter((p, i) => i === 0 || p !== parts[i - 1]).join(' › ');
}

export function defaultOf(n: FormNode): FormValue | undefined {
  switch (n.kind) {
    case 'group':
    case 'unknown':
      return undefined;
    default:
      return n.default;
  }
}
