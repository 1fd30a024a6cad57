import { rangeText, toNumber, type FormValue, type ValueNode, type FormSchema } from './ir';

/**
 * Client-side validation, as the user types. It mirrors what the schema says (range, integer,
 * ratio, required, options); controller-side rules arrive later as server errors.
 * Returns the message to show under the field, or null when the value is acceptable.
 */
export function validateValue(node: ValueNode, v: FormValue | undefined, schema?: FormSchema): string | null {
  if (v === undefined) return 'Required';
  switch (node.kind) {
    case 'boolean':
      return typeof v === 'boolean' ? null : 'Must be on or off';
    case 'discrete':
      return typeof v === 'string' && node.options.includes(v) ? null : 'Choose one of the options';
    case 'string':
      if (typeof v !== 'string') return 'Must be text';
      return v.trim() === '' ? 'Required' : null;
    case 'variant': {
      if (typeof v !== 'string') return 'Choose one of the options';
      if (!schema) return null;
      const keys = node.children.map((c) => schema.nodes.get(c)?.key);
      return keys.includes(v) ? null : 'Choose one of the options';
    }
    case 'integer':
    case 'float': {
      if (typeof v !== 'number' && typeof v !== 'string') return 'Must be a number';
      if (typeof v === 'string' && v.trim() === '') return 'Required';
      const n = toNumber(v);
      if (!Number.isFinite(n)) return 'Not a number';
      if (node.kind === 'integer' && !Number.isInteger(n)) return 'Must be a whole number';
      if (n < node.min || n > node.max) return `Out of range (${rangeText(node.min, node.max, node.unit)})`;
      return null;
    }
    case 'ratio': {
      if (typeof v !== 'object') return 'Must be a ratio';
      if (String(v.numerator).trim() === '' || String(v.denominator).trim() === '') return 'Required';
      const num = toNumber(v.numerator);
      const den = toNumber(v.denominator);
      if (!Number.isFinite(num) || !Number.isFinite(den)) return 'Not a number';
      if (den === 0) return 'The denominator must not be zero';
      const r = num / den;
      if (r < node.min || r > node.max) return `Ratio out of range (${rangeText(node.min, node.max)})`;
      return null;
    }
  }
}
