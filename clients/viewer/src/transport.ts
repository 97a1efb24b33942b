// Cap'n Proto RPC over a browser WebSocket: one capnp message (unpacked, with its
// segment table) per binary WebSocket message, as the server's WebSocketMessageStream
// sends and expects them. capnp-es ships no transport of its own; this is its Transport
// interface (sendMessage, recvMessage, close) with a queue, so that messages arriving
// while the connection is busy are kept in order.
import { Message } from "capnp-es";
import { Message as RpcMessage } from "capnp-es/capnp/rpc";

export class WebSocketTransport {
  private queue: ArrayBuffer[] = [];
  private waiting: { resolve: (m: RpcMessage) => void; reject: (e?: unknown) => void } | null = null;
  private closed = false;
  bytesReceived = 0;
  messagesReceived = 0;
  lastMessageBytes = 0;
  onClose: (reason: string) => void = () => {};

  private constructor(private socket: WebSocket) {
    socket.binaryType = "arraybuffer";
    socket.onmessage = (event: MessageEvent) => {
      const data = event.data as ArrayBuffer;
      this.bytesReceived += data.byteLength;
      this.messagesReceived += 1;
      this.lastMessageBytes = data.byteLength;
      if (this.waiting) {
        const w = this.waiting;
        this.waiting = null;
        this.deliver(data, w);
      } else {
        this.queue.push(data);
      }
    };
    socket.onclose = (event: CloseEvent) => {
      this.closed = true;
      // capnp-es ends its receive loop quietly on a rejection with no error.
      this.waiting?.reject(undefined);
      this.waiting = null;
      this.onClose(event.reason || `connection closed (code ${event.code})`);
    };
  }

  // Opens ws(s)://host/rpc of the page's own server (or `url`).
  static connect(url: string): Promise<WebSocketTransport> {
    return new Promise((resolve, reject) => {
      const socket = new WebSocket(url);
      socket.onopen = () => resolve(new WebSocketTransport(socket));
      socket.onerror = () => reject(new Error(`cannot open ${url}`));
    });
  }

  private deliver(data: ArrayBuffer, w: { resolve: (m: RpcMessage) => void; reject: (e?: unknown) => void }) {
    try {
      w.resolve(new Message(data, false).getRoot(RpcMessage));
    } catch (error) {
      w.reject(error);
    }
  }

  // capnp-es hands over the root struct of the RPC message; its message is sent whole.
  sendMessage(msg: RpcMessage): void {
    if (this.closed) return;
    this.socket.send(msg.segment.message.toArrayBuffer());
  }

  recvMessage(): Promise<RpcMessage> {
    if (this.closed) return Promise.reject(undefined);
    return new Promise((resolve, reject) => {
      const next = this.queue.shift();
      if (next) this.deliver(next, { resolve, reject });
      else this.waiting = { resolve, reject };
    });
  }

  close(): void {
    this.closed = true;
    this.socket.close();
  }
}
